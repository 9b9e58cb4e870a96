"""Shared setup of the tools tests.

The binding and CLI tests run against the package INSTALLED in the interpreter's
environment (``tools/bootstrap.sh`` installs ./tools into .venv), because only that copy
has the compiled extension ``graspguide.core._core``. Other test modules put ``tools/`` at the
front of ``sys.path`` to reach the pure-Python reference; importing the installed
package here, first, keeps ``graspguide`` the installed one for the whole session.
"""

from __future__ import annotations

import os
import pathlib
import signal
import sys

import pytest

# A suite started as a background job of a non-interactive shell (a CI runner's, or
# `cmd &` in a script) inherits SIGINT ignored, and exec keeps an ignored signal ignored
# in every child: the commands under test would then never see the Ctrl-C the tests
# send. A handler here is reset to the default by exec, as a terminal's children have it.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

TESTS_DIR = os.path.dirname(os.path.abspath(__file__))
TOOLS_DIR = os.path.dirname(TESTS_DIR)
REPO_ROOT = os.path.dirname(TOOLS_DIR)
KNOWN_ANSWERS = os.path.join(REPO_ROOT, "test", "data", "known_answers.json")
EXAMPLES = os.path.join(TOOLS_DIR, "examples", "solve_requests.jsonl")

_saved_path = list(sys.path)
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.getcwd()) != TOOLS_DIR]
try:
    import graspguide  # noqa: E402

    try:
        from graspguide.core import _core  # noqa: E402,F401
    except ImportError as e:  # pragma: no cover - setup problem
        _CORE_ERROR = (
            f"graspguide.core._core is not importable ({e}); graspguide comes from "
            f"{os.path.dirname(graspguide.__file__)}. Run `bash tools/bootstrap.sh` "
            "and the tests with .venv/bin/python (tools/run-tests.sh does both)."
        )
    else:
        _CORE_ERROR = None
finally:
    sys.path[:] = _saved_path


@pytest.fixture(scope="session")
def core():
    if _CORE_ERROR:
        pytest.fail(_CORE_ERROR)
    from graspguide.core import _core as module

    return module


def small_protocol_toml(
    name: str,
    seed: int,
    participants: int = 2,
    timeout_s: float = 60.0,
    modalities: tuple[str, ...] = ("F+C", "Fperp+C", "F+V", "Fperp+V"),
    wrenches: int = 2,
    single_motor: int = 1,
    familiarization_trials: int = 0,
) -> str:
    """A study protocol file (docs/study.md) with the paper's three-finger hand, small
    enough for a test: its sessions, wrenches and timeout as given."""
    mods = ", ".join(f'"{m}"' for m in modalities)
    return f"""
[study]
name = "{name}"
seed = {seed}
participants = {participants}
pose_rate_hz = 100.0

[trial]
threshold_deg = 3.0
hold_s = 0.5
timeout_s = {timeout_s!r}
constraints = "paper"
start_quat = [1.0, 0.0, 0.0, 0.0]

[hand]
units = "m"
y_axis = [0.0, 1.0, 0.0]

[hand.k3]
thumb  = [0.045, 0.045, 0.035]
index  = [0.015, 0.095, 0.040]
middle = [-0.010, 0.100, 0.040]

[conditions]
modalities = [{mods}]
contact_counts = [3]

[wrenches]
count = {wrenches}
single_motor = {single_motor}

[familiarization]
trials = {familiarization_trials}
"""


def subprocess_env() -> dict:
    """Environment for CLI subprocesses: no PYTHONPATH (it could put tools/, without the
    compiled extension, in front of the installed package)."""
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    env["PYTHONIOENCODING"] = "utf-8"
    return env


@pytest.fixture(scope="session")
def sketch_build(tmp_path_factory):
    """The Pro Mini sketch, built once per test run with arduino-cli into a temporary
    folder (graspguide.promini.build): no test depends on a build left in build/promini."""
    from graspguide.promini import build

    return build.build_sketch(pathlib.Path(REPO_ROOT), tmp_path_factory.mktemp("promini_sketch"))


@pytest.fixture(scope="session")
def sketch_elf(sketch_build) -> str:
    """Its ELF, for --port promini-sim (graspguide.devices.promini_sim: pass it as ``elf=`` or
    in $GRASPGUIDE_PROMINI_ELF to a command)."""
    return str(sketch_build.elf)


# --------------------------------------------------------------------------------------
# Devices: `--port PATH` runs the hardware subset of test_device_e2e.py against a board;
# without it those tests are skipped (and say so). The simulated-device tests always run.
# --------------------------------------------------------------------------------------
HARDWARE_SKIP_REASON = (
    "hardware test: no board given; run pytest with --port PATH "
    "(e.g. --port /dev/ttyACM0) to run it against a real device"
)


def pytest_addoption(parser):
    group = parser.getgroup("graspguide", "GraspGuide device tests")
    group.addoption(
        "--port",
        action="store",
        default=None,
        metavar="PATH",
        help="serial port of a GraspGuide board: runs the hardware tests of "
        "test_device_e2e.py against it (skipped without this option)",
    )
    group.addoption(
        "--baud",
        action="store",
        type=int,
        default=115200,
        metavar="RATE",
        help="baud rate for --port (default 115200)",
    )


@pytest.fixture(scope="session")
def hardware_port(request):
    """The --port given on the command line; skips the test without one."""
    port = request.config.getoption("--port")
    if not port:
        pytest.skip(HARDWARE_SKIP_REASON)
    return port


def running_in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """Under CI=true a skip is a failure (the QEMU firmware tests without QEMU or their
    ELF, a missing data file, ...): CI promises that every check that can run here ran.
    Only the hardware tests still skip, since no board is attached to a CI machine (the
    simulated device runs the same checks)."""
    outcome = yield
    report = outcome.get_result()
    if report.skipped and running_in_ci() and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        if HARDWARE_SKIP_REASON not in reason:
            report.outcome = "failed"
            report.longrepr = f"CI=true: this test may not skip here: {reason}"


# Figures the device tests measure (start time, frames/s, latencies, agreement counts),
# printed together at the end of the run so they show in tools/run-tests.sh's output.
_MEASUREMENTS = []


@pytest.fixture(scope="session")
def report_figure():
    """report_figure(name, value_text): one line in the end-of-run summary."""

    def add(name: str, text: str) -> None:
        _MEASUREMENTS.append((name, text))

    return add


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if _MEASUREMENTS:
        terminalreporter.section("device measurements")
        width = max(len(n) for n, _ in _MEASUREMENTS)
        for name, text in _MEASUREMENTS:
            terminalreporter.write_line(f"{name:<{width}}  {text}")


# --------------------------------------------------------------------------------------
# Tiers. `cross`: the test launches a cross toolchain or runs another CPU's code (QEMU or
# arm-none-eabi, avr-gcc or simavr, arduino-cli, mpy-cross). `slow`: it needs none of them
# but takes seconds to minutes on two cores (over about 3 s under a full run's load).
# `bash tools/run-tests.sh --fast` leaves both out (-m "not (cross or slow)"); the full run
# runs every test. The markers are registered in tools/pyproject.toml (--strict-markers).
# They are given here, from what a test uses: its module, a fixture, a fixture
# parametrized with a device port, or the test itself (its function's name, every
# parameter). A name below that its module does not define fails the collection, so a
# renamed test cannot slip into the fast tier unnoticed.
# --------------------------------------------------------------------------------------
# Module -> what each of its tests launches.
CROSS_MODULES = {
    "test_qemu_firmware.py": "QEMU runs the m4f firmware",
    "test_promini_build.py": "arduino-cli and avr-gcc build the Pro Mini sketch",
}
# Fixture -> what it launches; "module.py::name" is a module's own fixture.
CROSS_FIXTURES = {
    "sketch_build": "arduino-cli and avr-gcc build the Pro Mini sketch",
    "sketch_elf": "arduino-cli and avr-gcc build the Pro Mini sketch",
    "test_avr_frame.py::measured": "avr-gcc builds the per-frame layer, simavr runs it",
    "test_promini_sim.py::runner": "the simavr runner is built against libsimavr",
    "test_promini_sim.py::echo_elf": "avr-gcc builds a UART echo sketch",
}
# A fixture parametrized with one of these ports starts that device.
CROSS_PORTS = {
    "qemu": "QEMU runs the m4f firmware",
    "promini-sim": "simavr runs the Pro Mini sketch",
}
# "module.py" -> (what its tests below launch themselves, [test function names]).
CROSS_TESTS = {
    "test_latency.py": ("QEMU runs the m4f firmware", ["test_latency_on_qemu"]),
    "test_latency_lsl.py": ("QEMU runs the m4f firmware", ["test_tracker_latency_on_qemu"]),
    "test_motors_cmd.py": (
        "QEMU runs the m4f firmware",
        [
            "test_ctrl_c_leaves_the_qemu_firmwares_motor_registers_off",
            "test_port_qemu_starts_the_firmware_and_drives_it",
        ],
    ),
    "test_device_builds.py": (
        "arduino-cli builds the Pro Mini sketch, simavr runs it",
        ["test_the_readmes_promini_sim_latency_works_on_a_fresh_checkout"],
    ),
    "test_micropython_port.py": (
        "mpy-cross compiles the port",
        ["test_every_module_of_the_port_compiles_with_mpy_cross"],
    ),
    "test_mp_tools.py": (
        "graspguide mp build/deploy compiles with mpy-cross",
        [
            "test_mp_build_stages_the_boards_file_system",
            "test_mp_build_of_a_module_that_is_not_micropython_names_file_and_line",
            "test_mp_build_of_native_code_needs_an_arch",
            "test_mp_build_of_the_real_port",
            "test_mp_deploy_and_run_command_lines",
            "test_mp_deploy_without_mpremote_fails_naming_the_fix",
            "test_mp_deploy_and_run_end_to_end_on_the_interpreter",
            "test_mp_deploy_of_the_real_port_loads_its_plan_and_levels_on_the_interpreter",
        ],
    ),
}
# Fixture -> why it is slow; "module.py::name" is a module's own fixture.
SLOW_FIXTURES = {
    "test_float_paper_agreement.py::run": "solves thousands of random paper scenes twice",
}
# "module.py" -> (why the tests below are slow, [test function names]).
SLOW_TESTS = {
    "test_analysis.py": (
        "runs the paper's protocol for a participant on the simulated device",
        ["test_pilot_of_one_real_participant_run_is_analysed"],
    ),
    "test_device_builds.py": (
        "pio builds the simulated device from nothing",
        [
            "test_a_missing_simulated_device_is_built_on_first_use_showing_progress",
            "test_building_the_qemu_firmware_as_its_error_says_keeps_the_simulated_device",
        ],
    ),
    "test_device_log_damaged.py": (
        "runs a study on the simulated device",
        ["test_on_the_simulated_device_a_damaged_record_is_run_again_once_and_named"],
    ),
    "test_hostless_device_rules.py": (
        "runs a host-less study on the simulated device",
        ["test_a_study_with_one_sample_stamped_back_runs_that_trial_again_once"],
    ),
    "test_hostless_study.py": (
        "runs host-less studies on the simulated device",
        [
            "test_one_participants_hostless_study_finishes_and_analyses",
            "test_an_imu_fault_mid_trial_is_reported_counted_and_the_study_goes_on",
            "test_ctrl_c_stops_the_run_and_the_same_device_resumes_it",
            "test_a_sigkill_mid_study_loses_no_completed_trial_record",
            "test_under_a_tilted_mount_the_devices_error_follows_the_true_error",
            "test_resuming_under_another_calibration_is_refused_naming_both",
            "test_the_plans_calibration_shapes_every_telemetry_pwm",
            "test_cli_usage_errors",
            "test_with_the_default_noise_the_means_are_the_bias_and_gravity",
        ],
    ),
    "test_mp_tools.py": (
        "mpremote downloads records through the MicroPython interpreter",
        ["test_mp_log_downloads_the_boards_records_as_device_log_does"],
    ),
    "test_micropython_formats.py": (
        "a study's plan and records through the MicroPython interpreter",
        [
            "test_the_port_reads_the_plan_and_records_the_cpp_device_stored",
            "test_the_cpp_device_reads_the_records_and_plan_the_port_wrote",
        ],
    ),
    "test_micropython_port.py": (
        "the port's own tests in the MicroPython interpreter",
        ["test_port_tests_pass_inside_the_micropython_interpreter"],
    ),
    "test_micropython_solve.py": (
        "solves the hard paper scenes in emulated float32",
        ["test_emulated_float32_on_the_hard_paper_scenes"],
    ),
    "test_demo.py": (
        "runs demo studies on simulated devices",
        [
            "test_demo_killed_mid_study_resumes_every_trial_exactly_once",
            "test_demo_prints_tables_and_writes_figure",
            "test_pipelined_and_lockstep_runs_give_identical_trials",
        ],
    ),
    "test_plots.py": (
        "runs trials and draws their figures",
        [
            "test_a_fresh_simulated_run_plots",
            "test_cli_writes_png_and_svg",
            "test_cli_one_trial_and_format",
            "test_bad_input",
        ],
    ),
    "test_torn_records.py": (
        "analyses and plots a study in subprocesses",
        [
            "test_analyze_reads_every_complete_record_and_says_what_to_do",
            "test_plot_draws_the_complete_trials_and_says_what_was_left_out",
        ],
    ),
    "test_calibration_cli.py": (
        "whole calibrations in subprocesses",
        [
            "test_file_lists_every_trial_typed",
            "test_operator_ctrl_c_during_a_stimulus",
            "test_virtual_participant_on_sim",
            "test_operator_full_run_and_apply",
            "test_usage_errors",
        ],
    ),
    "test_cli_papercuts.py": (
        "a trial or an analysis into a closed pipe",
        [
            "test_stream_into_a_closed_pipe_stops_the_motors",
            "test_trial_into_a_closed_pipe_stops_the_motors_and_keeps_the_records",
            "test_analyze_into_a_closed_pipe_ends_quietly",
        ],
    ),
    "test_device_e2e.py": (
        "many graspguide subprocesses on the simulated device",
        [
            "test_killed_host_turns_motors_off_within_the_watchdog",
            "test_stale_stream_turns_motors_off_within_the_watchdog",
            "test_cli_solve_device_usage_errors",
            "test_cli_device_engine_answers_bad_requests_like_the_core",
            "test_cli_device_engine_agrees_on_the_known_answers",
            "test_cli_device_engine_agrees_on_the_examples",
            "test_cli_info_and_ports",
        ],
    ),
    "test_reference.py": (
        "the pure-Python reference on many scenes",
        [
            "test_known_answers_reproduce",
            "test_margin_agrees_with_enumeration",
            "test_scaled_quaternion_equals_unit",
            "test_qp_optimum_is_the_projection",
        ],
    ),
    "test_runner_calibration.py": (
        "runs trials on the simulated device",
        [
            "test_trial_applies_the_stored_calibration",
            "test_a_bad_calibration_file_stops_the_run_before_the_device",
        ],
    ),
    "test_replay_log.py": (
        "streams and replays a trial",
        ["test_a_stream_log_replays_as_the_same_trial"],
    ),
    "test_sim_children.py": (
        "interrupts trials on the simulated device",
        ["test_interrupted_trial_stops_cleanly_and_leaves_no_simulator"],
    ),
    "test_operator_runner.py": (
        "drives the operator console in a pty through whole trials",
        [
            "test_tlx_anchors_shown_per_scale_with_the_virtual_participant_as_a_person",
            "test_ready_prompt_rest_and_every_key_logged_against_its_trial",
            "test_ctrl_c_then_resume_honours_the_skip_and_the_redo",
        ],
    ),
    "test_trial_panel.py": (
        "runs trials with the TLX questionnaire in a pty",
        [
            "test_the_tlx_answers_are_reviewed_before_they_are_saved",
            "test_tlx_answers_from_input_that_is_not_a_terminal_are_saved_as_given",
        ],
    ),
    "test_runner.py": (
        "runs and kills studies on the simulated device",
        [
            "test_kill_mid_study_and_resume_every_trial_exactly_once",
            "test_real_time_run_on_the_device_clock",
        ],
    ),
    "test_sim_safety.py": (
        "waits out the watchdog in real time",
        [
            "test_a_host_that_stops_reading_loses_whole_answers_only",
            "test_no_request_keeps_the_motors_on_past_the_watchdog_with_a_1mib_store",
            "test_virtual_clock_trial_of_a_silent_host_ends_in_real_time",
        ],
    ),
    "test_hostless_clock.py": (
        "runs host-less plans against a paused host",
        [
            "test_a_host_paused_mid_run_finds_the_device_ahead_and_runs_the_plan",
            "test_a_host_slowed_at_start_finds_the_device_ahead_and_runs_the_plan",
        ],
    ),
    "test_stream_panel.py": (
        "streams to the live panel in a pty",
        [
            "test_panel_in_a_pty_shows_states_in_order",
        ],
    ),
    "test_sweep.py": (
        "runs sweeps of trials",
        [
            "test_tiny_sweep_end_to_end_and_resume",
            "test_larger_threshold_never_makes_the_same_trajectory_take_longer",
        ],
    ),
    "test_lsl_inlet.py": (
        "streams trials from a live LSL outlet in real time",
        [
            "test_a_stream_trial_from_lsl_matches_the_same_poses_replayed",
            "test_cli_lists_streams_and_refuses_a_missing_stream",
        ],
    ),
    "test_lab_streams.py": (
        "streams and runs trials from lab-stream sources",
        [
            "test_stream_lsl_matches_the_session_log",
            "test_trial_lsl_matches_the_trial_records",
            "test_observer_interface_pushes_in_order",
        ],
    ),
    "test_trial_lsl.py": (
        "runs `graspguide trial` from a live LSL outlet in real time",
        [
            "test_trial_from_lsl_matches_the_same_motion_replayed_and_a_stall_is_no_fault",
            "test_a_silent_stream_ends_the_run_unrecorded_and_a_resume_completes_it",
        ],
    ),
    "test_natnet_source.py": (
        "runs `graspguide trial` from a stand-in NatNet server in real time",
        ["test_trial_from_natnet_succeeds_both_trials"],
    ),
    "test_latency_lsl.py": (
        "streams a real LSL outlet's samples to the simulated device",
        ["test_tracker_latency_on_sim"],
    ),
    "test_bench.py": (
        "solves the benchmark's scene sets",
        [
            "test_instances_are_the_paper_hand_and_seeded_random_hands",
            "test_accuracy_set_is_more_hands_under_every_combination",
            "test_bad_options_are_clear_errors",
        ],
    ),
    "test_stream_pacing.py": (
        "streams a trial to the simulated device",
        [
            "test_stream_to_the_simulated_device_is_not_paced",
        ],
    ),
    "test_motors_cmd.py": (
        "switches the simulated device's motors in a subprocess",
        [
            "test_motors_on_sim_prints_a_trace_and_switches_off",
        ],
    ),
    "test_bench_targets.py": (
        "waits for a hanging QEMU's timeout",
        [
            "test_qemu_that_hangs_is_killed_at_the_timeout",
        ],
    ),
    "test_disk_faults.py": (
        "runs trials onto a size-limited disk",
        [
            "test_trial_on_a_size_limit_stops_with_one_line_and_resumes",
        ],
    ),
    "test_stream_interrupt.py": (
        "interrupts a stream in a pty",
        [
            "test_ctrl_c_in_a_terminal_leaves_the_panel_stopped_with_the_motors_off",
        ],
    ),
}


def _tier_reasons(item) -> dict[str, str]:
    """{"cross" and/or "slow": why} for one collected test, from the tables above."""
    module = item.path.name
    reasons = {}
    if module in CROSS_MODULES:
        reasons["cross"] = CROSS_MODULES[module]
    for name in item.fixturenames:
        for marker, table in (("cross", CROSS_FIXTURES), ("slow", SLOW_FIXTURES)):
            why = table.get(name) or table.get(f"{module}::{name}")
            if why:
                reasons[marker] = f"fixture {name}: {why}"
    callspec = getattr(item, "callspec", None)
    for name, value in (callspec.params if callspec else {}).items():
        # A fixture's parameter only: a test parametrized directly with a port's name gets
        # the name, not the device.
        defs = item._fixtureinfo.name2fixturedefs.get(name, ())
        if isinstance(value, str) and value in CROSS_PORTS and any(d.params for d in defs):
            reasons["cross"] = f"fixture {name}={value}: {CROSS_PORTS[value]}"
    for marker, table in (("cross", CROSS_TESTS), ("slow", SLOW_TESTS)):
        why, tests = table.get(module, ("", ()))
        if item.originalname in tests:
            reasons[marker] = why
    return reasons


def _check_tier_tables(items) -> None:
    """Every module and module-qualified name in the tables exists (a test module's
    function or fixture of that name, checked when the module is collected)."""
    modules = {item.path.name: item.module for item in items if hasattr(item, "module")}
    on_disk = {p.name for p in pathlib.Path(TESTS_DIR).rglob("test_*.py")}
    stale = []
    names = [k.partition("::")[::2] for k in (*CROSS_FIXTURES, *SLOW_FIXTURES) if "::" in k]
    for table in (CROSS_TESTS, SLOW_TESTS):
        names += [(module, test) for module, (_, tests) in table.items() for test in tests]
    for module in (*CROSS_MODULES, *CROSS_TESTS, *SLOW_TESTS):
        if module not in on_disk:
            stale.append(module)
    for module, name in names:
        if module in modules and not hasattr(modules[module], name):
            stale.append(f"{module}::{name}")
    if stale:
        raise pytest.UsageError(
            "tools/tests/conftest.py marks tests, fixtures or modules that do not exist "
            "(renamed? rename them there too): " + ", ".join(sorted(set(stale)))
        )


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(session, config, items):
    _check_tier_tables(items)
    for item in items:
        for marker, why in _tier_reasons(item).items():
            item.add_marker(getattr(pytest.mark, marker)(reason=why))
