"""Shared fixtures: tiny painted garages made deterministically by the scripted painter."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402

from garage_mj import Garage  # noqa: E402
from garage_mj.grid.painters import paint_garage  # noqa: E402

SHIPPED_MAPS = ["tiny_7x11", "m4_13x13_offset", "m5_13x13_aligned", "m6_13x13_s", "m7_13x13_u"]


@pytest.fixture(scope="session")
def painted_tiny() -> Garage:
    """A usable painted tiny_7x11 garage (same every run)."""
    return paint_garage("tiny_7x11", seed=1)


@pytest.fixture(scope="session")
def painted_maps() -> dict[str, Garage]:
    """One usable painted garage per shipped map (same every run)."""
    return {m: paint_garage(m, seed=3) for m in SHIPPED_MAPS}


JUNCTIONS_7X11 = """\
2 2 2 2 2 2 2 2 8 2 2
2 0 0 1 1 1 1 0 1 0 2
2 0 0 1 0 0 1 0 1 0 2
2 1 1 1 1 1 1 1 1 0 2
2 0 1 0 0 0 1 0 0 0 2
2 0 1 0 0 0 1 0 0 0 2
2 2 7 2 2 2 2 2 2 2 2"""


@pytest.fixture(scope="session")
def junction_garage() -> Garage:
    """A hand-drawn usable tiny garage with two adjacent T junctions, a cross, a loop and a dead end."""
    import numpy as np

    from garage_mj.grid.map_io import load_map
    from garage_mj.grid.rules import apply_stall_rule

    grid = np.array([[int(v) for v in line.split()] for line in JUNCTIONS_7X11.splitlines()])
    return Garage(apply_stall_rule(grid, "NS"), load_map("tiny_7x11").initial, name="junctions_7x11")


#: The slowest tests (8-22 s each on 2 cores: Ray clusters, whole demos, real kill -9 of CLI runs), kept out
#: of ``make test`` so it stays under 10 minutes on a fresh clone; ``make test-all`` runs them too.
SLOW = frozenset({
    "tests/test_ray_cluster.py::test_cluster_fills_the_library_the_local_pool_does",
    "tests/test_ray_cluster.py::test_a_lost_node_resumes_from_the_heads_checkpoint",
    "tests/test_ray_backend.py::test_workers_get_the_env_and_a_lost_worker_is_retried_then_named",
    "tests/test_ray_backend.py::test_hunt_on_ray_gives_the_local_hunt",
    "tests/test_ray_backend.py::test_a_job_past_its_time_limit_or_lost_for_good_goes_to_on_lost",
    "tests/test_ray_backend.py::test_cruise_rows_equal_local_and_a_rerun_resumes",
    "tests/test_ray_backend.py::test_generation_experiment_on_ray_gives_the_same_runs",
    "tests/test_pytest_plugin.py::test_park_tests_of_a_driver_pass_with_the_oracle_and_fail_readably_standing_still",
    "tests/test_cruise.py::test_cli_videos_of_the_batch_in_out",
    "tests/test_drivers.py::test_cli_user_driver_by_file_and_by_module_in_two_workers",
    "tests/test_faults.py::test_kill_9_mid_export_then_resume",
    "tests/test_faults.py::test_kill_9_during_the_first_cruise_test_then_resume",
    "tests/test_faults.py::test_demo_with_a_map_path_writes_only_inside_out",
    "tests/test_faults.py::test_two_cruise_runs_into_one_folder",
    "tests/test_training.py::test_crash_then_resume_keeps_every_garage_once",
    "tests/test_train_driver.py::test_hunt_curriculum_trains_on_the_garages_its_hunt_found",
    "tests/test_generator.py::test_search_stage_fills_a_low_band_the_rollouts_never_reach",
    # each a second test of a kind make test runs (so make test stays under 10 minutes): a hunt's repeat and resume
    # (test_hunt.py), a read-only library and output (test_read_only_library_lists_and_read_only_out_is_one_line),
    # a driver that never returns (test_faults.py), a read-only export target (the CARLA package's), a killed worker
    # (test_faults.py's cruise worker)
    "tests/test_hunt_park.py::test_the_same_seed_gives_the_same_hunt",
    "tests/test_faults.py::test_writing_into_a_read_only_library_is_one_line",
    "tests/test_pytest_plugin.py::test_a_driver_that_never_returns_fails_as_driver_timeout",
    "tests/test_park_problems.py::test_a_read_only_park_problems_target_is_one_line_naming_it",
    "tests/test_train_driver.py::test_a_killed_env_worker_is_one_line_that_says_resume",
    # and: a driver process that dies (test_a_driver_that_segfaults_is_a_driver_crash_and_the_run_ends), a kill -9 of
    # a generation run (test_cli_generation.py), an export folder given as cases (test_an_exported_park_problem_runs_
    # end_to_end), a newcomer's path through the docs (the parking one, test_a_newcomer_brings_their_own_parking_stack,
    # with the README's plugin example, test_the_readme_example_passes)
    "tests/test_faults.py::test_kill_9_of_a_cruise_worker_is_retried_and_the_run_completes",
    "tests/test_protocol_status.py::test_status_after_a_real_kill_9",
    "tests/test_park_cases.py::test_a_folder_of_an_export_stands_for_its_json_problems",
    "tests/test_docs.py::test_a_newcomer_follows_the_docs_to_their_own_driver",
    # and: difficulty fit and score from runs on the command line (the park runs', test_cli_fits_and_scores_park_runs_
    # beside_the_levels; the route fit itself in test_fit_is_monotone_and_finds_what_makes_tests_fail)
    "tests/test_route_difficulty.py::test_fit_and_score_from_a_cruise_run",
})


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.nodeid.split("[")[0] in SLOW:
            item.add_marker(pytest.mark.slow)
