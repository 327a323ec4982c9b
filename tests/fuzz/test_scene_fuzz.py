"""Fuzzing the scene loaders (TOML and Mitsuba XML): mutated scene files give a scene that renders, or a
clear SceneError naming the file -- never another exception, a non-finite pixel or a hang (see
fuzz/scene_fuzzer.py).  The default run tries a bounded, reproducible set of cases per format
(``derandomize``); the slow run thousands."""
from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings

from fuzz.scene_fuzzer import FORMATS, Case, cases, check_case

FUZZ = dict(derandomize=True, database=None, deadline=None, print_blob=False,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])


def fuzz(format_name: str, examples: int) -> None:
    """Check ``examples`` cases of a format (hypothesis reports the smallest failing one)."""
    @settings(max_examples=examples, **FUZZ)
    @given(case=cases(format_name))
    def run(case: Case):
        check_case(case, format_name)

    run()


@pytest.mark.parametrize("format_name", sorted(FORMATS))
@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # trimesh and NumPy on broken mesh files
@pytest.mark.filterwarnings("ignore::pathspace.scene.mitsuba_xml.MitsubaWarning")
def test_mutated_scene_files_load_or_fail_clearly(format_name):
    fuzz(format_name, 200)


@pytest.mark.slow
@pytest.mark.parametrize("format_name", sorted(FORMATS))
@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # trimesh and NumPy on broken mesh files
@pytest.mark.filterwarnings("ignore::pathspace.scene.mitsuba_xml.MitsubaWarning")
def test_thousands_of_mutated_scene_files(format_name):
    fuzz(format_name, 5000)
