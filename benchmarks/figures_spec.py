"""The rendering spec of docs/figures.md's generated tables (rendered by ``python benchmarks/figures.py``).

Each table names its columns; each row its key, the benchmark run whose JSON holds its figures
(``benchmarks/results/RESULT.json``; a table with ``result`` set takes all its rows from that one run and says its
command and date below it, otherwise each row gets "how" and "when" columns), the cells that are not measured (what
is measured, the target: targets live here, never in a benchmark's output) and, for a measured JSON, a
``str.format`` template per measured column over its ``figures``. A transcribed JSON gives the measured cells'
text itself, dated.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Row:
    key: str
    result: str | None
    cells: dict[str, str]
    templates: dict[str, str] = field(default_factory=dict)
    how_note: str = ""
    # (figure, limit) or (figure, ">=", limit): a measured row's first template cell starts "met: " when the figure
    # is at most (at least) the limit, else "**not met**: " (the target column says the same limit in words); a
    # figure inside a dict is named with dots ("sdk_as_log.vs_before")
    met_if: tuple | None = None
    met_column: str | None = None  # the cell the verdict starts (default: the first measured one)


def _auto_row(figures: str, build: str, spinner: str, fmt: str) -> Row:
    """A row of the parallel-auto table: the benchmark's figures of one build and load (``figures``, a dict)."""
    return Row(figures.replace("_", "-"), None, {"build": build, "spinner": spinner},
               templates={"auto": f"{{{figures}[auto_s]:{fmt}}} s", "off": f"{{{figures}[off_s]:{fmt}}} s",
                          "auto / off": f"{{{figures}[ratio]:.2f}}", "auto chose": f"{{{figures}[chose]}}"})


@dataclass(frozen=True)
class Table:
    name: str
    columns: tuple[str, ...]
    rows: tuple[Row, ...]
    result: str | None = None


TABLES = (
    Table("calibration", ("what", "target", "measured",), result=None, rows=(
        Row("payload", "calibration",
            {"what": "payload recovered",
             "target": "within 2 %"}),
        Row("offset", "calibration",
            {"what": "offset recovered",
             "target": "within 1 ms"}),
        Row("runs", "calibration",
            {"what": "runs of the scenario the fit took",
             "target": "- (reported)"}),
        Row("residual", "calibration",
            {"what": "joints' RMS residual, start -> fitted",
             "target": "the noise"}),
        Row("linked", "calibration",
            {"what": "the payload linked on plant and controller (`--fit plant.mass.payload,ctl.mass.payload`)",
             "target": "not identifiable from the joints"}),
        Row("pool", "calibration",
            {"what": "two runs of a two-value Jacobian on the sweep's pool of 2 against in the process",
             "target": "-"}),
    )),
    Table("speed", ("what", "target", "measured",), result=None, rows=(
        Row("native-vs-python", "native",
            {"what": "10 s of helix_ctc_analytic on native FMUs against helix_ctc on python FMUs (full Exudyn plant), "
                     "no log, each scenario's own parallel setting, loop wall time",
             "target": "10x faster"}),
        Row("native-fmus-per-step", "native",
            {"what": "each native FMU in helix_ctc_analytic, serial, `component_time_s` per 1 ms step: traj / ik / "
                     "ctl / plant",
             "target": "2 us each"}),
        Row("master-two-c-fmus", "master_native",
            {"what": "the master's own cost per step on two C FMUs (VanDerPol -> Feedthrough), over a bare Python "
                     "loop of the same FMI calls",
             "target": "2 us"},
            templates={"measured": "{two_own_c_us:.2f} us ({two_master_c_us:.2f} against {two_bare_us:.2f} us a step; "
                                   "with the calls made from Python: {two_own_python_us:.2f} us). On 2026-11-28: "
                                   "0.49-0.59 us (from Python 2.79-2.88 us, not met)"},
            met_if=("two_own_c_us", 2.0)),
        Row("master-own-helix", "master_overhead",
            {"what": "the master's own cost per step on helix_ctc_analytic's four native FMUs (everything outside "
                     "their FMU calls: loop, link copies, status and NaN checks, component timings, the watchdog's "
                     "record, the tracking error), serial, no log: the loop's wall time per step over a bare C loop "
                     "of the same FMI calls on the same FMUs",
             "target": "1 us"},
            templates={"measured": "{helix_own_c_us:.2f} us with the loop in C ({helix_loop_c_us:.2f} against "
                                   "{helix_bare_us:.2f} us a step, best of the rounds); the same loop in Python: "
                                   "{helix_own_python_us:.1f} us (per component a closure, five clock readings, the "
                                   "tracking observer in Python). Three runs on 2026-11-29 (load about 1): 0.51, 0.56, "
                                   "0.71 us; before the C loop's arrays of a block's step times were filled whole "
                                   "(element by element through ctypes, 0.59 us a step), the same day: 1.36 and 1.39 "
                                   "us, 1.15 us at the previous day's last commit; on 2026-11-28 at load 0.3-4.5 0.56-"
                                   "0.71 us were measured too (best of 5 to 15 rounds: take 15 rounds, the machine's "
                                   "runs fall in two speed bands)"},
            met_if=("helix_own_c_us", 1.0)),
        Row("jacobi-vs-gauss-seidel", "master_native",
            {"what": "the Jacobi loop against the Gauss-Seidel loop, helix_ctc_analytic native, serial, no log, wall "
                     "time per step, alternated",
             "target": "1.15x"},
            templates={"measured": "{jacobi_ratio_c:.2f}x with the loop in C ({jacobi_c_us:.2f} / "
                                   "{gauss_seidel_c_us:.2f} us), {jacobi_ratio_python:.2f}x with the loop in Python "
                                   "({jacobi_python_us:.2f} / {gauss_seidel_python_us:.2f} us). On 2026-11-28: 1.00x "
                                   "in C (2.67 / 2.67 us, 15 rounds, load 2.5), 0.99x in Python (8.81 / 8.76 us); 5 "
                                   "rounds on a loaded machine scatter (1.08-1.26x). Before Jacobi took one C call "
                                   "per component: 2.0x (21.2 against 10.5 us, old and new loops alternated in one "
                                   "process)"},
            how_note="(part 3)",
            met_if=("jacobi_ratio_c", 1.15)),
        Row("plant-in-run", "plant_step-in_run",
            {"what": "helix_ctc's plant component per step (serial, no log) against the linear full plant's step of "
                     "`benchmarks/plant_step.py`, alternated in one process",
             "target": "1.15x"}),
        Row("me-derivative", "native",
            {"what": "one derivative evaluation of the native ME plant through the master (set time, set states, get "
                     "derivatives, finite check)",
             "target": "2 us"}),
        Row("helix-ctc-me-native", "native",
            {"what": "helix_ctc_me on native FMUs against helix_ctc_analytic on native FMUs, both serial",
             "target": "- (reported)"}),
        Row("helix-ctc-native-vs-monolithic", "native",
            {"what": "helix_ctc with native trajectory, IK and CTC and the Exudyn plant, serial, against the "
                     "monolithic loop of `benchmarks/helix_ctc.py`",
             "target": "1.10x"}),
        Row("logged-vs-unlogged", "logged_run",
            {"what": "helix_ctc_analytic on native FMUs, every signal logged to MCAP against unlogged",
             "target": "2x"},
            templates={"measured": "{ratio median:.1f}x (rounds {ratio min:.1f}-{ratio max:.1f}x): the loop {loop "
                                   "logged s (median):.3f} s logged against {loop unlogged s (median):.3f} s unlogged "
                                   "(medians), the whole call {whole call logged s (median):.2f} against {whole call "
                                   "unlogged s (median):.2f} s; per logged step the master's own logging work {master "
                                   "logging work us/step (median):.1f} us and {blocked on writer pipe us/step "
                                   "(median):.1f} us blocked on the writer's pipe; the writer process {writer process "
                                   "us/step:.1f} us per step (its loop replayed alone)"},
            met_if=("ratio median", 2.0)),
        Row("numbers-routing", "core-numbers",
            {"what": "the python float path of the core (IK step, CTC law, forward dynamics, plant step) with "
                     "branches routed through the number namespace (`where`, `check`) so that the formulas trace to "
                     "C, against the same formulas without that routing (the commit before the one `git log -S "
                     "_where_scalar delta/numbers.py` shows)",
             "target": "not slower"}),
        Row("plant-step-linear", "plant_step",
            {"what": "Exudyn plant, 1 ms step, linear full / lumped",
             "target": "300 / 30 us"}),
        Row("plant-step-rotary", "plant_step",
            {"what": "Exudyn plant, 1 ms step, rotary full / lumped",
             "target": "600 / - us"}),
        Row("plant-step-before", "plant_step",
            {"what": "full plants' 1 ms step against the plants before the rods became end-point masses and Newton's "
                     "tolerance was tightened (in the same process, interleaved), linear / rotary",
             "target": "0.5x each"}),
        Row("master-overhead-trivial", "master_overhead",
            {"what": "master overhead per step, 4 trivial FMUs, no logging",
             "target": "15 us"},
            templates={"measured": "{trivial_overhead_us:.1f} us ({trivial_master_us:.1f} against "
                                   "{trivial_bare_us:.1f} us per step): the master's loop in C makes from C the calls "
                                   "the bare loop makes from Python, so it runs below the bare calls (2026-11-28 at "
                                   "load 2.3: -8.1 us, 13.6 against 21.7 us; before the loop in C: 2.76 us over, 12.3 "
                                   "against 9.5 us)"},
            met_if=("trivial_overhead_us", 15.0)),
        Row("master-overhead-trivial-logged", "master_overhead",
            {"what": "the same, every signal logged to MCAP",
             "target": "30 us"},
            templates={"measured": "{trivial_overhead_logged_us:.1f} us ({trivial_master_logged_us:.1f} us per step; "
                                   "one C call per step, the log's observers in Python after it; 2026-11-28: -3.7 us, "
                                   "18.0 us per step; before the loop in C: 10.2 us, 19.8 us per step)"},
            met_if=("trivial_overhead_logged_us", 30.0)),
        Row("mcap-writer", "mcap_writer",
            {"what": "MCAP writer, helix_ctc's logged messages replayed: foxglove-sdk as the log writer uses it (zstd "
                     "1, compression in the calling thread) / foxglove-sdk (zstd 3, a file object) / a hand-packed "
                     "mcap 1.x writer (zstd 3, kept in the benchmark to measure against) / mcap's public "
                     "`add_message`",
             "target": "at least as fast as the hand-packed writer"},
            templates={"measured": "{sdk_as_log[us_per_step]:.1f} / {sdk_file[us_per_step]:.1f} / "
                                   "{sink[us_per_step]:.1f} / {public[us_per_step]:.1f} us per step: "
                                   "{sdk_as_log[vs_before]:.2f}x / {sdk_file[vs_before]:.2f}x / 1 / "
                                   "{public[vs_before]:.2f}x; files {sdk_as_log[file_mb]:.1f} / "
                                   "{sdk_file[file_mb]:.1f} / {sink[file_mb]:.1f} / {public[file_mb]:.1f} MB "
                                   "({messages} messages, {steps} steps). In an earlier run (undated, with other work "
                                   "on the machine; foxglove-sdk at zstd 1 as the recorder's): 7.3 / 8.8 / 11.4 / "
                                   "20.8 us per step, 1.55x / 1.29x / 1 / 0.55x, another run 1.37x at zstd 3"},
            met_if=("sdk_as_log.vs_before", ">=", 1.0)),
        Row("helix-ctc-parallel", "helix_ctc",
            {"what": "10 s of helix_ctc, no logging, parallel (the default)",
             "target": "5 s wall"},
            templates={"measured": "{loop_s[parallel]:.2f} s (serial {loop_s[serial]:.2f} s; best of the rounds). On "
                                   "2026-11-26 (three runs, quiet, converged plant steps, rods as end-point masses): "
                                   "1.34-1.44 s, serial 1.30-1.42 s; with rigid-body rods 1.85-1.90 / 1.73-1.77 s"},
            met_if=("loop_s.parallel", 5.0)),
        Row("helix-ctc-logged", "helix_ctc",
            {"what": "10 s of helix_ctc, every signal logged (what `cosim run` does), parallel",
             "target": "-"},
            templates={"measured": "{loop_s[parallel_log]:.2f} s (serial {loop_s[serial_log]:.2f} s; whole call with "
                                   "start-up {whole_call_s[parallel_log]:.2f} s). On 2026-11-26: 1.42-1.49 s (serial "
                                   "1.44 s; whole call 1.58 s); with rigid-body rods 1.97 / 2.13 s"}),
        Row("helix-ctc-vs-monolithic", "helix_ctc",
            {"what": "helix_ctc against a monolithic in-process loop (same plant, kinematics and CTC law, no FMI), "
                     "parallel",
             "target": "ratio 1.3"},
            templates={"measured": "{ratio_to_monolithic[parallel]:.2f} ({loop_s[parallel]:.2f} s against "
                                   "{loop_s[mono]:.2f} s; with the log {ratio_to_monolithic[parallel_log]:.2f}). On "
                                   "2026-11-26: 0.99-1.04 (1.34-1.44 s against 1.35-1.39 s; with the log 1.02-1.03)"},
            met_if=("ratio_to_monolithic.parallel", 1.3)),
        Row("helix-ctc-vs-monolithic-serial", "helix_ctc",
            {"what": "the same, serial (`parallel: off`)",
             "target": "ratio 1.3"},
            templates={"measured": "{ratio_to_monolithic[serial]:.2f} ({loop_s[serial]:.2f} s against "
                                   "{loop_s[mono]:.2f} s). On 2026-11-26: 0.94-0.97 (1.73-1.77 s against 1.81-1.84 s)"},
            met_if=("ratio_to_monolithic.serial", 1.3)),
        Row("long-run", "long_run",
            {"what": "level helix under CTC, full plants, no logging: linear 600 s / rotary 300 s simulated "
                     "(`helix_ctc_level`, `rotary_helix_ctc_level`)",
             "target": "complete"}),
        Row("exit-stress", "exit_stress",
            {"what": "consecutive short runs, solver failures and end stops included",
             "target": "no abnormal exit"}),
        Row("model-exchange", "model_exchange",
            {"what": "10 s of helix_ctc_me (analytic plant as FMI 3 model exchange, integrated by the master with "
                     "`dopri5` in C) against helix_ctc_analytic (the same dynamics as a CS FMU integrating itself "
                     "with RK4), native FMUs, serial, no log; the ME plant within 1e-6 m of the CS plant",
             "target": "ratio 1.5"},
            templates={"measured": "{paired_ratio_dopri5:.2f}, the median of the alternated rounds' ratios (the "
                                   "bests of the rounds: {me_dopri5_s:.3f} s against {cs_s:.3f} s, {ratio_dopri5:.2f}: "
                                   "this machine's runs fall in two speed bands, and a best of each side may come from "
                                   "different bands; four runs of 12 rounds gave medians 1.40-1.45, bests 1.31-1.56, before an accepted "
                                   "state's outputs and end-stop checks were made one call); "
                                   "the ME plant within {distance_dopri5_m:.2g} m of the CS plant. The CS plant takes one RK4 "
                                   "step of 4 evaluations per 1 ms inside the FMU, the ME plant a DOPRI5 step of 6 "
                                   "evaluations plus one after the input changed, each through the FMI exchange; both "
                                   "integrate the platform dynamics (the ME plant's states are p, v; its joint outputs "
                                   "are computed when read), and the FMU's parameter-only constants are recomputed on "
                                   "a flag, not by comparing the parameters at each evaluation. `cvode` in C "
                                   "{ratio_cvode:.1f} ({me_cvode_s:.2f} s: BDF restarts at order one every step; "
                                   "{distance_cvode_m:.2g} m). Before, with the joints q, qd as states (a joint-space "
                                   "evaluation, twice the platform one) and the parameters compared at each call: "
                                   "1.72 at load 7 (2026-11-29), 1.68 best-of on a quiet machine; before the "
                                   "integration in C: 5.19 with `dop853` (3.38 s against 0.651 s)"},
            met_if=("paired_ratio_dopri5", 1.5)),
        Row("core-ik-step", "core",
            {"what": "the kinematics and dynamics core per call against the plain-float code it replaced (parent of "
                     "the commit that removed `delta/scalar_kinematics.py`), linear / rotary: IK step (IK, joint "
                     "limits, qd, qdd)",
             "target": "not slower"}),
        Row("core-ctc-fd", "core",
            {"what": "the same: CTC law / forward dynamics (joint coordinates)",
             "target": "not slower"}),
        Row("core-cs-plant", "core",
            {"what": "the same: the analytic CS plant's 1 ms step (RK4 in platform coordinates, against SciPy's "
                     "DOP853 at rtol 1e-10 over the joint dynamics)",
             "target": "not slower"}),
        Row("analytic-vs-exudyn-python", "core",
            {"what": "10 s of helix_ctc_analytic (analytic CS plant) against helix_ctc (full Exudyn plant), python "
                     "FMUs, no logging, each scenario's own parallel setting",
             "target": "4x faster"}),
        Row("ceiling", "core",
            {"what": "the ceiling: the rest of that run plus a plant of FMI exchange only (its component time when "
                     "its `advance` and `refresh` are no-ops)",
             "target": "-"}),
        Row("recording-read", "recording_read",
            {"what": "reading the JointState topic (3 joints, 1 kHz, 60 s: 60 000 messages) of a 1.01 GB ROS 2 MCAP "
                     "bag that also holds 6 000 messages of 168 kB on another topic, header stamps, each read in a "
                     "fresh process, against a 12 MB bag of the JointState messages alone, alternated",
             "target": "memory flat"}),
    )),
    Table("state-and-events", ("what", "figure",), result=None, rows=(
        Row("fmu-state-native", "fmu_state",
            {"what": "get + set FMU state, native FMUs"},
            templates={"figure": "get {native_get_us:.2f} us, set {native_set_us:.2f} us per call over the "
                                 "{native_fmus} native FMU builds (worst {native_worst_us:.2f} us), of which "
                                 "{native_floor_us:.2f} us is ctypes' own call; {native_state_per_step:.1f} of one "
                                 "doStep of the same FMU. On 2026-11-28, quiet: get 0.35-0.39, set 0.38-0.44 us "
                                 "(worst of 40 builds 0.85 / 0.94 us), ctypes 0.22 us"},
            met_if=("native_worst_us", 1.0)),
        Row("fmu-state-python", "fmu_state",
            {"what": "get + set FMU state, python FMUs"},
            templates={"figure": "`{python_fmu}` {python_get_us:.1f} + {python_set_us:.1f} us (its doStep through the "
                                 "same calls {python_step_us:.0f} us; 2026-11-28: 3.5 + 10.2 us, doStep 76 us); the "
                                 "Exudyn plants (`--python-fmu` naming them), 2026-11-28 at load about 3: 0.26-0.30 + "
                                 "0.36-0.63 ms (about one plant step)"},
            how_note="(the python line), [fmus.md](fmus.md#fmu-state-of-the-python-fmus)"),
        Row("checkpoint-exudyn", "checkpoint",
            {"what": "checkpoint of helix_ctc at T = 5 s (Exudyn plant)"}),
        Row("checkpoint-native", "checkpoint-native",
            {"what": "checkpoint of helix_ctc_analytic at T = 5 s (native)"},
            templates={"figure": "written in {write_ms:.1f} ms, {bytes} bytes; loop {loop_ratio:.2f}x; resume "
                                 "{resume_ratio:.2f}x a fresh one-step run ({resume_s:.3f} / {fresh_s:.3f} s). On "
                                 "2026-11-28, quiet: 4.1 ms, 3 882 bytes; 1.06x; 1.12x (0.034 / 0.031 s)"}),
        Row("state-event", "checkpoint",
            {"what": "locating a state event (`plant.p.x < 0.0003`, the helix a little before 0.5 s, 9 steps after "
                     "the last save)"}),
        Row("warm-sweep", "warm_sweep",
            {"what": "warm sweep, 8 cases of helix_ctc_analytic from a checkpoint at 5 s against the same cold"},
            templates={"figure": "cold / warm {speedup_median:.2f}x ({cold_median_s:.2f} / {warm_median_s:.2f} s, "
                                 "median of the runs, on the embedded pool of forked workers), each case's stepping "
                                 "{stepping_speedup_median:.2f}x. On 2026-11-28 at load 5.8-5.9: 2.22x (1.65 / 3.66 "
                                 "s), stepping 2.66x; on Dask's `LocalCluster` before 2026-11-28: 1.08-1.18x, its "
                                 "start-up dominated"},
            how_note=", [sweeps.md](sweeps.md#warm-sweeps-from-a-checkpoint)"),
    )),
    Table("sweeps",
          ("sweep, native FMUs",
          "target",
          "serial loop",
          "serial, prepared",
          "sweep (2 workers)",
          "speed-up over the loop / over the prepared loop",),
          result=None, rows=(
        Row("cases-32-short", "sweep-32",
            {"sweep, native FMUs": "32 cases of 0.1 s",
             "target": "1.5x"},
            templates={"serial loop": "{serial_median_s:.2f} s",
                       "serial, prepared": "{prepared_median_s:.2f} s",
                       "sweep (2 workers)": "{sweep_median_s:.2f} s",
                       "speed-up over the loop / over the prepared loop": "{speedup_median:.2f}x (runs "
                                                                          "{speedup_runs:.2f}x) / "
                                                                          "{speedup_prepared_median:.2f}x "
                                                                          "({speedup_prepared_runs:.2f}x); 2026-11-28 "
                                                                          "at load 1.3-2.5: 2.87x / 1.59x"},
            met_if=("speedup_median", ">=", 1.5),
            met_column="speed-up over the loop / over the prepared loop"),
        Row("cases-100-short", "sweep-100",
            {"sweep, native FMUs": "100 cases of 0.1 s",
             "target": "1.7x"},
            templates={"serial loop": "{serial_median_s:.2f} s",
                       "serial, prepared": "{prepared_median_s:.2f} s",
                       "sweep (2 workers)": "{sweep_median_s:.2f} s",
                       "speed-up over the loop / over the prepared loop": "{speedup_median:.2f}x (runs "
                                                                          "{speedup_runs:.2f}x) / "
                                                                          "{speedup_prepared_median:.2f}x "
                                                                          "({speedup_prepared_runs:.2f}x); 2026-11-28 "
                                                                          "at load 1.3-2.5: 2.56x / 1.61x"},
            met_if=("speedup_median", ">=", 1.7),
            met_column="speed-up over the loop / over the prepared loop"),
        Row("cases-100-long", "sweep-100x10",
            {"sweep, native FMUs": "100 cases of 10 s",
             "target": "1.7x"},
            templates={"serial loop": "{serial_median_s:.1f} s",
                       "serial, prepared": "{prepared_median_s:.1f} s",
                       "sweep (2 workers)": "{sweep_median_s:.1f} s",
                       "speed-up over the loop / over the prepared loop": "{speedup_median:.2f}x (runs "
                                                                          "{speedup_runs:.2f}x) / "
                                                                          "{speedup_prepared_median:.2f}x "
                                                                          "({speedup_prepared_runs:.2f}x); 2026-11-28 "
                                                                          "(the standard library's pool): 1.55x, not "
                                                                          "met / 1.20x"},
            met_if=("speedup_median", ">=", 1.7),
            met_column="speed-up over the loop / over the prepared loop"),
    )),
    Table("startup", ("whole process", "median", "best",), result="startup", rows=(
        Row("ours", None,
            {"whole process": "`python -m cosim run ... --stop-time 0.01`"},
            templates={"median": "{ours_median_s:.3f} s",
                       "best": "{ours_best_s:.3f} s"}),
        Row("libcosim", None,
            {"whole process": "libcosimpy `from_ssp_file` + `simulate_until`"},
            templates={"median": "{libcosim_median_s:.3f} s",
                       "best": "{libcosim_best_s:.3f} s"}),
        Row("help", None,
            {"whole process": "`python -m cosim --help`"},
            templates={"median": "{help_median_s:.3f} s",
                       "best": "{help_best_s:.3f} s"}),
        Row("python", None,
            {"whole process": "`python -c pass`"},
            templates={"median": "{python_median_s:.3f} s",
                       "best": "{python_best_s:.3f} s"}),
        Row("ratio", None,
            {"whole process": "ours / libcosim (target at most 1.5x)"},
            templates={"median": "{ratio_of_medians:.1f}x",
                       "best": "{ratio_of_best:.1f}x"}),
    )),
    Table("startup-imports", ("top-level import", "ms", "what it is",), result="startup", rows=(
        Row("cosim.engine.overrides", None,
            {"top-level import": "`cosim.engine.overrides`",
             "what it is": "the scenario schema: pydantic and its models, numpy (through the time grid), yaml, the "
                           "plugins' discovery (`importlib.metadata` entry points)"},
            templates={"ms": "{imports_ms[cosim.engine.overrides]:.0f}"}),
        Row("cosim.robot.preflight", None,
            {"top-level import": "`cosim.robot.preflight`",
             "what it is": "the delta plugin, loaded when the schema checks the trajectory's type: `fmus.registry` "
                           "(what each FMU is; its adapter and native model load only for a build), the workspace "
                           "check"},
            templates={"ms": "{imports_ms[cosim.robot.preflight]:.0f}"}),
        Row("fmpy", None,
            {"top-level import": "`fmpy`",
             "what it is": "reading the model descriptions (lxml, attrs)"},
            templates={"ms": "{imports_ms[fmpy]:.0f}"}),
        Row("cosim.run", None,
            {"top-level import": "`cosim.run`",
             "what it is": "the engine, the FMU access layer, the observers"},
            templates={"ms": "{imports_ms[cosim.run]:.0f}"}),
        Row("cosim.cli", None,
            {"top-level import": "`cosim.cli`",
             "what it is": "argparse and every command's parser"},
            templates={"ms": "{imports_ms[cosim.cli]:.0f}"}),
        Row("delta.trajectories", None,
            {"top-level import": "`delta.trajectories`",
             "what it is": "the trajectory and its workspace check"},
            templates={"ms": "{imports_ms[delta.trajectories]:.0f}"}),
        Row("cosim.engine.supervision", None,
            {"top-level import": "`cosim.engine.supervision`",
             "what it is": "the supervisor (multiprocessing, subprocess)"},
            templates={"ms": "{imports_ms[cosim.engine.supervision]:.0f}"}),
    )),
    Table("parallel-auto",
          ("build",
          "spinner",
          "auto",
          "off",
          "auto / off",
          "auto chose",),
          result="parallel_auto", rows=(
        _auto_row("native", "native", "no", ".3f"),
        _auto_row("python", "python", "no", ".2f"),
        _auto_row("native_spinner", "native", "yes", ".3f"),
        _auto_row("python_spinner", "python", "yes", ".2f"),
    )),
    Table("pick-place-payload",
          ("run",
          "RMSE x / y / z (um)",
          "max \\|p - p_ref\\| carrying (after each pick)",
          "after each place",
          "max \\|u\\| carrying",),
          result="pick_place_payload", rows=(
        Row("empty", None,
            {"run": "empty gripper"},
            templates={"RMSE x / y / z (um)": "{empty[rmse_um][0]:.1f} / {empty[rmse_um][1]:.1f} / "
                                              "{empty[rmse_um][2]:.1f}",
                       "max \\|p - p_ref\\| carrying (after each pick)": "{empty[carrying_error_um]:.0f} um",
                       "after each place": "{empty[placed_error_um]:.0f} um",
                       "max \\|u\\| carrying": "{empty[carrying_effort_N]:.1f} N"}),
        Row("told", None,
            {"run": "part, controller told"},
            templates={"RMSE x / y / z (um)": "{told[rmse_um][0]:.1f} / {told[rmse_um][1]:.1f} / "
                                              "{told[rmse_um][2]:.1f}",
                       "max \\|p - p_ref\\| carrying (after each pick)": "{told[carrying_error_um]:.0f} um",
                       "after each place": "{told[placed_error_um]:.0f} um",
                       "max \\|u\\| carrying": "{told[carrying_effort_N]:.1f} N"}),
        Row("untold", None,
            {"run": "part, controller not told"},
            templates={"RMSE x / y / z (um)": "{untold[rmse_um][0]:.1f} / {untold[rmse_um][1]:.1f} / "
                                              "{untold[rmse_um][2]:.1f}",
                       "max \\|p - p_ref\\| carrying (after each pick)": "{untold[carrying_error_um]:.0f} um",
                       "after each place": "{untold[placed_error_um]:.0f} um",
                       "max \\|u\\| carrying": "{untold[carrying_effort_N]:.1f} N"}),
    )),
)
