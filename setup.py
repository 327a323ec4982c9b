"""Build of the C extension pathspace._native (the rest lives in pyproject.toml)."""
import numpy
from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "pathspace._native",
            sources=["ext/module.c", "ext/embree_loader.c", "ext/accel.c", "ext/mis.c", "ext/geometry.c",
                     "ext/shadow.c", "ext/primary.c", "ext/paths.c", "ext/film.c", "ext/lights.c", "ext/camera.c",
                     "ext/direct.c", "ext/scatter.c", "ext/warp.c", "ext/lanes.c", "ext/pt_vertex.c",
                     "ext/lens_connect.c", "ext/join.c"],
            depends=["ext/native.h", "ext/embree4_api.h", "ext/shadow.h", "ext/light_sample.h", "ext/direct.h",
                     "ext/scatter.h", "ext/warp.h", "ext/camera.h", "ext/diffuse.h"],
            include_dirs=["ext", numpy.get_include()],
            extra_compile_args=["-O3", "-std=c11", "-D_GNU_SOURCE", "-Wall", "-Wextra",
                                "-Wno-missing-field-initializers", "-ffp-contract=off"],
            libraries=["dl", "pthread", "m"],
        )
    ]
)
