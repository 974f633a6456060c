"""Hostile inputs, round 3: the classes around issue 25's cases, through ``python -m cosim`` as a user runs it.

Numbers (every numeric option, every number of a scenario: nan, infinities, past the largest time or double),
files that are not regular files (a FIFO, a device), and more. Each case asserts the exit code, one line naming
the cause, no traceback, an empty temporary folder (the ``run`` fixture of ``test_hostile``) and no output left.
"""

from __future__ import annotations

import html
import json
import os
import re
from pathlib import Path

import pytest
from test_faults import SMALL, fails
from test_hostile import run  # noqa: F401 - the fixture: a private TMPDIR, left empty

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = ROOT / "tests" / "golden" / "helix_ctc.mcap"


@pytest.fixture
def small(write_scenario) -> Path:
    return write_scenario(SMALL)


# --------------------------------------------------------------------------- numbers given as options

# (command and options before the value, the option, a bad value): every numeric option refuses nan, infinities and
# values outside its range with argparse's error naming it (they were taken: --watchdog -1 and nan meant "no limit",
# --margin nan passed every check; or a traceback: --period nan, --seed -1, --spacing inf, robot ik 0 0 nan)
BAD_OPTIONS = [
    (("run", "{S}", "--no-log"), "--watchdog", "-1"),
    (("run", "{S}", "--no-log"), "--watchdog", "nan"),
    (("run", "{S}", "--no-log"), "--watchdog", "inf"),
    (("baseline", str(GOLDEN), "--out", "{T}/b.mcap"), "--period", "nan"),
    (("baseline", str(GOLDEN), "--out", "{T}/b.mcap"), "--period", "inf"),
    (("robot", "workspace", "--robot", "linear_delta_thesis"), "--spacing", "inf"),
    (("robot", "workspace", "--robot", "linear_delta_thesis"), "--margin", "nan"),
    (("robot", "singularity", "--robot", "linear_delta_thesis", "--p", "0", "0", "-0.6"), "--margin", "inf"),
    (("robot", "ik", "--robot", "linear_delta_thesis", "--margin", "0.01", "0", "0"), "Z", "nan"),
    (("robot", "workspace", "--robot", "linear_delta_thesis", "--cylinder", "0.01", "0.01", "{V}"), "--cylinder", "inf"),
    (("sweep", "{S}", "--out", "{T}/sw", "--random", "g.k=uniform(1,2)", "-n", "1"), "--seed", "-1"),
    (("sweep", "{S}", "--out", "{T}/sw", "--grid", "g.k=1"), "--workers", "100000"),
    (("validate-model", "--robot", "linear_delta_thesis"), "--duration", "inf"),
    (("validate-model", "--robot", "linear_delta_thesis"), "--w-rotation", "nan"),
    (("ssp", "export", "{S}", "-o", "{T}/x.ssp"), "--stop-time", "nan"),
    (("run", "{S}", "--no-log"), "--stop-time", "inf"),
    (("check", "{S}"), "--step", "-inf"),
]


@pytest.mark.parametrize("before, option, value", BAD_OPTIONS, ids=[f"{b[0]}{o}={v}" for b, o, v in BAD_OPTIONS])
def test_every_numeric_option_refuses_what_is_no_value_of_it(run, small, tmp_path, before, option, value):
    args = [a.replace("{S}", str(small)).replace("{T}", str(tmp_path)).replace("{V}", value) for a in before]
    if "{V}" not in before:  # a positional, or OPTION=VALUE (a value may start with -)
        args.append(value if not option.startswith("-") else f"{option}={value}")
    message = fails(run(*args), 2, f"argument {option}: expected a (finite|whole) number", f"got '{value}'",
                    usage=True)
    assert "invalid" not in message, message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml", "tmp"], "an output was written"


@pytest.mark.parametrize("args, cause", [
    (("--step", "1e308"), "step 1e\\+308 s is longer than the motion \\(0.5 s\\)"),
    (("--step", "0.5", "--duration", "0.1"), "step 0.5 s is longer than the motion \\(0.1 s\\)"),
    (("--duration", "9e9"), "9e\\+09 s at a step of 0.0002 s is 4.5e\\+13 plant steps, more than the 1e\\+06"),
    (("--step", "1e-300"), "is 5e\\+299 plant steps, more than the 1e\\+06 a prescribed run takes"),
])
def test_validate_model_refuses_a_step_past_the_motion_and_runs_past_its_limit(run, args, cause):
    """A finite step longer than the motion was 'operands could not be broadcast'; a huge duration or a tiny step
    allocated and ran billions of plant steps: one line each, before the plant is built."""
    fails(run("validate-model", "--robot", "linear_delta_thesis", "--trajectory", "pick_place", "--quiet", *args), 2,
          f"validate-model: .*{cause}")


def test_watchdog_zero_still_means_no_limit(run, small):
    assert run("run", small, "--no-log", "--quiet", "--watchdog", "0").returncode == 0


# --------------------------------------------------------------------------- numbers of a scenario

@pytest.mark.parametrize("args, cause", [
    (("--set", "time.stop=.inf"), "--set time.stop=.inf: Input should be a finite number"),
    (("--stop-time", "1e308"), "--stop-time 1e\\+308: Input should be less than or equal to 9000000000"),
    (("--step", "1e308"), "--step 1e\\+308: Input should be less than or equal to 9000000000"),
    (("--set", "time.start=1e308"), "--set time.start=1e308: Input should be less than or equal to 9000000000"),
    (("--set", "watchdog_s=.inf"), "--set watchdog_s=.inf: Input should be a finite number"),
    (("--set", "logging.flush_interval=.nan"), "--set logging.flush_interval=.nan: Input should be a finite number"),
    (("--set", "g.k=.inf"), "--set g.k=.inf: k is Real: expected a finite number, got inf"),
    (("--set", "g.k=1e400"), "--set g.k=1e400: k is Real: expected a finite number, got '1e400'"),
    (("--set", "g.k=" + "9" * 400), "k is Real: expected a finite number, got 999"),
])
@pytest.mark.parametrize("command", ["check", "run"])
def test_a_number_no_run_can_use_is_one_line_naming_it(run, small, tmp_path, command, args, cause):
    """Times past the longest grid (whose nanoseconds overflowed: a traceback blamed on 'an exit() inside a
    component'), infinities taken as a watchdog or a gain, a whole number past the largest double."""
    out = ["--out", tmp_path / "x.mcap"] if command == "run" else []
    fails(run(command, small, *args, *out), 2, cause)
    assert not list(tmp_path.glob("x.mcap*")), "a refused run left output files"


@pytest.mark.parametrize("line, cause", [
    ("time: {stop: 1e308, step: 0.01}", r"s.yaml:\d+: time.stop: Input should be less than or equal to 9000000000"),
    ("time: {stop: .inf, step: 0.01}", r"s.yaml:\d+: time.stop: Input should be a finite number"),
    ("time: {stop: 0.2, step: 0.01, start: 1e308}", r"s.yaml:\d+: time.start: Input should be less than or equal"),
    ("time: {stop: 0.2, step: .inf}", r"s.yaml:\d+: time.step: Input should be a finite number"),
])
def test_a_time_no_grid_can_hold_in_a_file_names_its_line(run, write_scenario, line, cause):
    fails(run("check", write_scenario(SMALL.replace("time: {stop: 0.2, step: 0.01}", line))), 2, cause)


@pytest.mark.parametrize("value, cause", [(".inf", "got inf"), ("-.inf", "got -inf"), ("1e400", "got '1e400'")])
def test_an_infinite_real_parameter_in_a_file_is_refused(run, write_scenario, value, cause):
    fails(run("check", write_scenario(SMALL.replace("k: 2.0", f"k: {value}"))), 2,
          r"s.yaml:\d+: components.g.parameters.k: k is Real: expected a finite number, " + cause)


# --------------------------------------------------------------------------- numbers inside other options

def test_a_baseline_period_below_the_stamps_resolution_is_refused(run, tmp_path):
    """1e-300 s is 0 ns: the decimation divided by zero, reported as a damaged log."""
    for period in ("1e-300", "1e308"):
        fails(run("baseline", GOLDEN, "--out", tmp_path / "b.mcap", "--period", period), 2,
              f"baseline period must be from 1 ns to 9e\\+09 s, got {period.replace('e', 'e[+]?')} s")
    assert not (tmp_path / "b.mcap").exists()


def test_an_infinite_tolerance_is_no_tolerance(run):
    fails(run("compare", GOLDEN, GOLDEN, "--tol", "plant.p=inf"), 2, "--tol 'plant.p=inf': expected "
          "SIGNAL_PATTERN=POSITIVE_NUMBER \\(finite\\)")


@pytest.mark.parametrize("dist", ["uniform(0,inf)", "uniform(-1e308,1e308)", "normal(nan,1)"])
def test_a_random_draw_over_no_finite_range_is_refused(run, small, tmp_path, dist):
    fails(run("sweep", small, "--random", f"g.k={dist}", "-n", "1", "--out", tmp_path / "sw", "--workers", "1"), 2,
          f"--random g.k={dist.replace('(', '[(]').replace(')', '[)]')}: the bounds must be finite numbers")
    assert not (tmp_path / "sw").exists()


# --------------------------------------------------------------------------- inputs that are not regular files

@pytest.fixture
def fifo(tmp_path) -> Path:
    """A FIFO nobody writes: reading it blocks for ever."""
    import os

    path = tmp_path / "fifo"
    os.mkfifo(path)
    return path


def _inputs(kind: str, tmp_path: Path, fifo: Path) -> tuple[Path, str]:
    """(a path of ``kind``, what the message says of it)."""
    if kind == "fifo":
        return fifo, r"not a regular file \(a FIFO\)"
    if kind == "device":
        return Path("/dev/zero"), r"not a regular file \(a character device\)"  # never ends
    d = tmp_path / "folder"
    d.mkdir(exist_ok=True)
    return d, "is a directory, not a file"


@pytest.mark.parametrize("kind", ["fifo", "device", "directory"])
@pytest.mark.parametrize("command", ["check", "run", "sweep", "ssp", "recover", "table", "report", "baseline",
                                     "compare", "from-log"])
def test_an_input_that_is_not_a_regular_file_is_refused_at_once(run, tmp_path, fifo, small, kind, command):
    """A FIFO, /dev/zero or a directory as a command's input: check, run and baseline hung reading a FIFO or
    /dev/zero, an .ssp that is one hung, and every log reader said 'no such file'."""
    path, says = _inputs(kind, tmp_path, fifo)
    if command == "ssp":  # an archive given by a name ending in .ssp: a link to it
        link = tmp_path / "archive.ssp"
        link.symlink_to(path)
        path = link
    out = tmp_path / "out.mcap"
    args = {"check": ("check", path), "run": ("run", path, "--out", out), "ssp": ("run", path, "--out", out),
            "sweep": ("sweep", path, "--grid", "g.k=1", "--out", tmp_path / "sw", "--workers", "1"),
            "recover": ("recover", path, "--out", out), "table": ("table", path),
            "report": ("report", path, "--out", tmp_path / "rep"), "baseline": ("baseline", path, "--out", out),
            "compare": ("compare", GOLDEN, path), "from-log": ("run", "--from-log", path, "--out", out)}[command]
    if command == "compare":  # named as a log
        link = tmp_path / "other.mcap"
        link.symlink_to(path)
        args = ("compare", GOLDEN, link)
    fails(run(*args, timeout=30), 2, says)
    assert not any(p.name.startswith(("out", "sw", "rep")) for p in tmp_path.iterdir()), sorted(tmp_path.iterdir())


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_a_component_whose_fmu_is_not_a_regular_file_is_named(run, write_scenario, tmp_path, fifo, kind):
    path, says = _inputs(kind, tmp_path, fifo)
    scenario = write_scenario(SMALL.replace("{CosimTSource}", str(path)))  # before the fixture fills it in
    fails(run("check", scenario, timeout=30), 2, r"s.yaml:\d+: components.src: ", says)


def test_a_scenario_file_larger_than_any_scenario_is_refused_unread(run, tmp_path):
    from cosim.engine.scenario import MAX_SCENARIO_BYTES

    big = tmp_path / "big.yaml"
    with big.open("wb") as f:
        f.truncate(MAX_SCENARIO_BYTES + 1)  # sparse: no disk
    fails(run("check", big, limit_memory=True), 2, f"big.yaml: the file is larger than "
                                                   f"{MAX_SCENARIO_BYTES // 2 ** 20} MiB")


# --------------------------------------------------------------------------- outputs that are not regular files

@pytest.mark.parametrize("command", ["baseline", "validate-model", "sweep-report"])
def test_no_output_replaces_a_fifo(run, tmp_path, fifo, small, command):
    """--out naming a FIFO (or, as root, a device: /dev/null became a regular file): refused before any work, the
    FIFO left as it was; run, recover and ssp export refused it already."""
    import stat

    sweep = tmp_path / "sw"
    if command == "sweep-report":
        assert run("sweep", small, "--grid", "g.k=1,2", "--out", sweep, "--workers", "1", "--quiet").returncode == 0
    args = {"baseline": ("baseline", GOLDEN, "--out", fifo),
            "validate-model": ("validate-model", "--robot", "linear_delta_thesis", "--out", fifo, "--quiet"),
            "sweep-report": ("sweep-report", sweep, "--out", fifo)}[command]
    fails(run(*args, timeout=60), 2, "fifo: is not a regular file")
    assert stat.S_ISFIFO(fifo.stat().st_mode), "the FIFO was replaced"
    assert not [p for p in tmp_path.rglob(".*") if p.is_file()], "a temporary output was left"


def test_a_baseline_never_writes_over_its_source_or_into_a_directory(run, tmp_path):
    import shutil

    log = tmp_path / "log.mcap"
    shutil.copy(GOLDEN, log)
    before = log.read_bytes()
    fails(run("baseline", log, "--out", log), 2, "log.mcap: is this command's own input")
    (tmp_path / "d.mcap").mkdir()
    fails(run("baseline", log, "--out", tmp_path / "d.mcap"), 2, "d.mcap: is a directory")  # was 'cannot read'
    assert log.read_bytes() == before


# --------------------------------------------------------------------------- a sweep's folder that is not one

@pytest.mark.parametrize("content, says", [
    (b"\xff\xfe garbage \x00\x01", "not a sweep's results table \\('utf-8' codec can't decode"),
    (b"a,b\n1,2,3\n", "not a sweep's results table \\(no case and status columns\\)"),
])
@pytest.mark.parametrize("command", ["sweep", "sweep-report"])
def test_a_results_table_that_is_not_one_is_named(run, tmp_path, small, content, says, command):
    sweep = tmp_path / "sw"
    sweep.mkdir()
    (sweep / "results.csv").write_bytes(content)
    args = ("sweep", small, "--grid", "g.k=1", "--out", sweep, "--workers", "1") if command == "sweep" else \
        ("sweep-report", sweep)
    fails(run(*args), 2, "results.csv: " + says)
    assert (sweep / "results.csv").read_bytes() == content


def test_a_sweep_json_or_metric_that_is_not_the_sweeps_is_named(run, tmp_path, small):
    sweep = tmp_path / "sw"
    assert run("sweep", small, "--grid", "g.k=1,2", "--out", sweep, "--workers", "1", "--quiet").returncode == 0
    (sweep / "sweep.json").write_text('{"parameters": 5}')
    fails(run("sweep-report", sweep), 2,
          "sweep.json: missing or without parameters \\(the columns of results.csv it swept\\)")
    (sweep / "sweep.json").write_text('{"parameters": [')
    fails(run("sweep-report", sweep), 2, "sweep.json: not the sweep's JSON")
    (sweep / "sweep.json").write_text('{"parameters": ["g.k"]}')
    fails(run("sweep-report", sweep, "--metric", "case"), 2, "results.csv: case [0-9a-f]+: case = '[0-9a-f]+' is "
                                                             "not a number")
    assert run("sweep-report", sweep).returncode == 0
    assert sorted(p.name for p in sweep.iterdir()) == ["results.csv", "sweep.json", "sweep_rmse.png"]


# --------------------------------------------------------------------------- SSP archives

@pytest.fixture
def small_ssp(run, small, tmp_path) -> Path:
    """SMALL exported as an SSP archive (src -> g, g's k in resources/g.ssv)."""
    ssp = tmp_path / "small.ssp"
    assert run("ssp", "export", small, "-o", ssp).returncode == 0
    return ssp


def _rewrite(ssp: Path, out: Path, ssd=lambda s: s, ssv=lambda s: s, extra=()) -> Path:
    """A copy of ``ssp`` with its .ssd and g.ssv edited and ``extra`` (name, bytes) members appended."""
    import warnings
    import zipfile

    with zipfile.ZipFile(ssp) as src, zipfile.ZipFile(out, "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            if name == "SystemStructure.ssd":
                data = ssd(data.decode()).encode()
            elif name == "resources/g.ssv":
                data = ssv(data.decode()).encode()
            dst.writestr(name, data)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # zipfile's "Duplicate name": wanted here
            for name, data in extra:
                dst.writestr(name, data)
    return out


def _annotated(ssd: str, **changes) -> str:
    """``ssd`` with our annotation's JSON given ``changes`` (the rest as exported)."""
    m = re.search(r"<dcs:Scenario>(.*)</dcs:Scenario>", ssd, flags=re.S)
    data = {**json.loads(html.unescape(m.group(1))), **changes}
    return ssd[:m.start(1)] + html.escape(json.dumps(data), quote=False) + ssd[m.end(1):]


U_INPUT = '<ssd:Connector name="u" kind="input">\n            <ssc:Real />'
BAD_SSP = {
    # an archive whose members repeat means one thing to one zip reader and another to the next (the last won)
    "duplicate_fmu": (dict(extra=[("resources/g.fmu", b"not a zip")]),
                      "the archive holds two members named 'resources/g.fmu': refused"),
    "duplicate_ssd": (dict(extra=[("SystemStructure.ssd", b"<x/>")]),
                      "the archive holds two members named 'SystemStructure.ssd'"),
    # connectors that say what their FMU's variables are not (taken as the FMU's); a kind SSP does not know is a
    # warning (test_a_connector_kind_ssp_does_not_know_is_one_warning)
    "kind_wrong": (dict(ssd=lambda s: s.replace(U_INPUT, U_INPUT.replace("input", "output"))),
                   "component 'g': connector 'u': declared an output, but its FMU's variable u is an input"),
    "type_wrong": (dict(ssd=lambda s: s.replace(U_INPUT, U_INPUT.replace("Real", "Boolean"))),
                   "component 'g': connector 'u': declared Boolean, but its FMU's variable u is Real"),
    # a parameter given twice in one set (the last won)
    "parameter_twice": (dict(ssv=lambda s: s.replace("</ssv:Parameters>", '<ssv:Parameter name="k"><ssv:Real '
                                                     'value="5"/></ssv:Parameter></ssv:Parameters>')),
                        "resources/g.ssv: parameter k is given twice"),
    # our annotation: JSON no scenario holds (tracebacks: nesting, a 5000-digit number; silently ignored or last)
    "annotation_deep": (dict(ssd=lambda s: s.replace('"description": ""', '"description": ' + "[" * 100_000
                                                     + "]" * 100_000)),
                        "annotation org.delta-cosim.engine.scenario: not a scenario's JSON \\(maximum recursion"),
    "annotation_digits": (dict(ssd=lambda s: s.replace('"flush_interval": 1.0', '"flush_interval": 1' + "0" * 5000)),
                          "annotation org.delta-cosim.engine.scenario: not a scenario's JSON \\(Exceeds the limit"),
    "annotation_key_twice": (dict(ssd=lambda s: s.replace('"name": "small",', '"name": "small", "name": "x",')),
                             "annotation org.delta-cosim.engine.scenario: the key 'name' is given twice"),
    "annotation_components": (dict(ssd=lambda s: s.replace('"name": "small",', '"name": "small", "components": '
                                                           '{"x": {"path": "/etc/passwd"}},')),
                              "annotation org.delta-cosim.engine.scenario: unknown key 'components'"),
    "annotation_not_object": (dict(ssd=lambda s: re.sub(r"<dcs:Scenario>.*</dcs:Scenario>",
                                                        "<dcs:Scenario>[1, 2]</dcs:Scenario>", s, flags=re.S)),
                              "annotation org.delta-cosim.engine.scenario: expected a JSON object, got list"),
    # JSON of the wrong shape inside the object (an internal error when the reader took it as options)
    "annotation_options_list": (dict(ssd=lambda s: _annotated(s, component_options=[1, 2])),
                                "annotation org.delta-cosim.engine.scenario: component_options must map component "
                                "names to objects of their options, got a list"),
    "annotation_options_values": (dict(ssd=lambda s: _annotated(s, component_options={"g": [1]})),
                                  "component_options must map component names to objects of their options, got an "
                                  "object of list"),
    "annotation_name_list": (dict(ssd=lambda s: _annotated(s, name=["small"])),
                             "annotation org.delta-cosim.engine.scenario: name must be a string, got a list"),
    # a stop time past the longest grid overflowed into a traceback
    "stop_past_the_grid": (dict(ssd=lambda s: s.replace('stopTime="0.2"', 'stopTime="1e308"')),
                           "time.stop: Input should be less than or equal to 9000000000"),
    "stop_nan": (dict(ssd=lambda s: s.replace('stopTime="0.2"', 'stopTime="NaN"')),
                 "time.stop: Input should be a finite number"),
}


@pytest.mark.parametrize("case", list(BAD_SSP))
@pytest.mark.parametrize("command", ["check", "run"])
def test_a_hostile_archive_is_one_line_naming_what_is_wrong(run, small_ssp, tmp_path, case, command):
    kwargs, says = BAD_SSP[case]
    bad = _rewrite(small_ssp, tmp_path / f"{case}.ssp", **kwargs)
    out = ["--out", tmp_path / "x.mcap"] if command == "run" else []
    fails(run(command, bad, *out), 2, re.escape(str(bad)) + ": ", says)
    assert not list(tmp_path.glob("x.mcap*")), "a refused archive left output files"


def test_a_connector_kind_ssp_does_not_know_is_one_warning(run, small_ssp, tmp_path):
    """libcosim's SSP parser stores a connector's kind unchecked and connects the FMU's variables; here too the
    FMU's variable decides (u is its input), with one warning naming component, connector and kind, and the run
    goes on. A kind that contradicts the FMU (kind_wrong) stays refused: the file says two things of one signal."""
    odd = _rewrite(small_ssp, tmp_path / "odd.ssp", ssd=lambda s: s.replace(U_INPUT, U_INPUT.replace("input",
                                                                                                      "sideways")))
    r = run("run", odd, "--out", tmp_path / "x.mcap", "--quiet")
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip().splitlines() == [
        "warning: odd.ssp: component 'g': connector 'u': kind 'sideways' is not an SSP connector kind (input, output, "
        "inout, parameter, calculatedParameter): its FMU's variable decides"], r.stderr


def test_the_archive_as_exported_still_runs(run, small_ssp, tmp_path):
    """The checks above refuse what is wrong only: the exporter's own archive checks and runs."""
    assert run("check", small_ssp).returncode == 0
    assert run("run", small_ssp, "--out", tmp_path / "x.mcap", "--quiet").returncode == 0


# --------------------------------------------------------------------------- FMUs whose modelDescription.xml lies

def _fmu_with(src: Path, out: Path, edit) -> Path:
    """A copy of the FMU ``src`` with its modelDescription.xml edited."""
    import zipfile

    with zipfile.ZipFile(src) as z, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for name in z.namelist():
            data = z.read(name)
            dst.writestr(name, edit(data.decode()).encode() if name == "modelDescription.xml" else data)
    return out


K_START = '<Real start="1"/>'
BAD_FMU = {
    # the model identifier names the library loaded: a path loaded one outside the FMU
    "identifier_path": (lambda s: s.replace('modelIdentifier="CosimTGain"', 'modelIdentifier="../../../../x/evil"'),
                        "coSimulation modelIdentifier '../../../../x/evil' is not a C identifier"),
    "identifier_absolute": (lambda s: s.replace('modelIdentifier="CosimTGain"', 'modelIdentifier="/x/evil"'),
                            "coSimulation modelIdentifier '/x/evil' is not a C identifier"),
    "identifier_missing": (lambda s: s.replace(' modelIdentifier="CosimTGain"', ""),
                           "coSimulation modelIdentifier None is not a C identifier"),  # was a NoneType + str
    "guid_missing": (lambda s: re.sub(r' guid="[^"]*"', "", s), "no guid"),  # was a NoneType .encode at t = 0
    # a parameter and an input on one value reference: refused where named (test_a_parameter_and_an_input_on_one_...)
    "negative_reference": (lambda s: s.replace('name="u" valueReference="1"', 'name="u" valueReference="-1"'),
                           "variable u: valueReference -1 is not an unsigned 32-bit integer"),
    # start, min and max of another type, or no number (taken, and never checked)
    "start_text": (lambda s: s.replace(K_START, '<Real start="abc"/>'), "variable k: start 'abc' is not a Real value"),
    "start_nan": (lambda s: s.replace(K_START, '<Real start="NaN"/>'),
                  "variable k \\(parameter\\): start 'NaN' is not a finite number"),
    "start_inf": (lambda s: s.replace(K_START, '<Real start="1e999"/>'),
                  "variable k \\(parameter\\): start '1e999' is not a finite number"),
    "min_text": (lambda s: s.replace(K_START, '<Real start="1" min="abc"/>'), "variable k: min 'abc' is not a Real"),
    # a NaN bound compares false: every value would pass the range check (an infinite one is no bound: it loads)
    "max_nan": (lambda s: s.replace(K_START, '<Real start="1" max="NaN"/>'),
                "variable k \\(parameter\\): max 'NaN' is not a finite number"),
}


@pytest.mark.parametrize("case", list(BAD_FMU))
def test_an_fmu_whose_description_lies_is_named_before_it_is_loaded(run, write_scenario, test_fmus, tmp_path, case):
    edit, says = BAD_FMU[case]
    fmu = _fmu_with(test_fmus["CosimTGain"], tmp_path / f"{case}.fmu", edit)
    scenario = write_scenario(SMALL.replace("{CosimTGain}", str(fmu)).replace("{k: 2.0}", "{}"))
    message = fails(run("run", scenario, "--out", tmp_path / "x.mcap"), 2,
                    r"s.yaml:\d+: components.g: " + re.escape(str(fmu)) + ": modelDescription.xml: ", says)
    assert "load library" not in message, message
    assert not list(tmp_path.glob("x.mcap*")), "a refused FMU left output files"


def test_a_name_declared_twice_is_refused_only_where_it_is_named(run, write_scenario, test_fmus, tmp_path):
    """Strict where it protects, lenient where other tools are (dp-ship's DPController.fmu declares iepsi twice;
    libcosim runs it): the FMU loads with one warning, its twice-declared name left out, and the run goes on; a
    scenario that sets or connects that name is refused, naming both value references."""
    fmu = _fmu_with(test_fmus["CosimTGain"], tmp_path / "twice.fmu",
                    lambda s: s.replace('name="y" valueReference="2"', 'name="k" valueReference="2"'))
    scenario = write_scenario(SMALL.replace("{CosimTGain}", str(fmu)).replace("{k: 2.0}", "{}"))
    r = run("run", scenario, "--out", tmp_path / "x.mcap")
    assert r.returncode == 0, r.stderr
    warnings = [ln for ln in r.stderr.splitlines() if ln.startswith("warning: ")]
    assert warnings == ["warning: twice.fmu: modelDescription.xml declares more than one variable named 'k' (value "
                        "references 0, 2): left out (not logged, not settable); the run goes on while nothing names "
                        "them"], r.stderr
    named = write_scenario(SMALL.replace("{CosimTGain}", str(fmu)), "named.yaml")  # sets g.k
    fails(run("run", named, "--out", tmp_path / "y.mcap"), 2, r"named.yaml:\d+: ",
          "twice.fmu declares 2 variables named 'k' \\(value references 0, 2\\): the name is ambiguous")


def test_an_infinite_min_or_max_is_no_bound(run, write_scenario, test_fmus, tmp_path):
    """FMI's min and max are xs:double, which holds INF; FMPy reads them as float('inf') and runs such an FMU. An
    infinite bound is no bound (the range check takes it so): the FMU loads and runs with a parameter set, where it
    was refused as 'not a finite number'; a value outside a finite bound beside it is still refused."""
    fmu = _fmu_with(test_fmus["CosimTGain"], tmp_path / "inf.fmu",
                    lambda s: s.replace(K_START, '<Real start="1" min="-INF" max="INF"/>'))
    r = run("run", write_scenario(SMALL.replace("{CosimTGain}", str(fmu))), "--out", tmp_path / "x.mcap", "--quiet")
    assert r.returncode == 0 and not r.stderr.strip(), r.stderr
    half = _fmu_with(test_fmus["CosimTGain"], tmp_path / "half.fmu",
                     lambda s: s.replace(K_START, '<Real start="1" min="-INF" max="1.5"/>'))
    fails(run("run", write_scenario(SMALL.replace("{CosimTGain}", str(half)), "half.yaml"), "--out",
              tmp_path / "y.mcap"), 2, r"half.yaml:\d+: ", "is outside its declared range \\[-INF, 1.5\\]")


def test_an_empty_range_is_one_warning_and_refused_where_a_value_is_set(run, write_scenario, test_fmus, tmp_path):
    """FMPy (its validation included) and libcosim do not compare min with max, and run such an FMU; so do we, with
    one warning naming the variable, while nothing sets it. A value set there is refused as outside the range,
    naming the scenario's line: the check applies where the range is used."""
    fmu = _fmu_with(test_fmus["CosimTGain"], tmp_path / "empty.fmu",
                    lambda s: s.replace(K_START, '<Real start="1" min="5" max="0"/>'))
    r = run("run", write_scenario(SMALL.replace("{CosimTGain}", str(fmu)).replace("{k: 2.0}", "{}")), "--out",
            tmp_path / "x.mcap", "--quiet")
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip().splitlines() == [
        "warning: empty.fmu: modelDescription.xml: variable k (min 5 > max 0): no value is in the declared range; the "
        "run goes on, and a value set there is refused as outside it"], r.stderr
    fails(run("run", write_scenario(SMALL.replace("{CosimTGain}", str(fmu)), "set.yaml"), "--out",
              tmp_path / "y.mcap"), 2, r"set.yaml:\d+: ", "k = 2.0 is outside its declared range \\[5, 0\\]")


def test_a_parameter_and_an_input_on_one_value_reference_are_refused_only_where_named(run, write_scenario, test_fmus,
                                                                                      tmp_path):
    """An alias set holds at most one parameter or input (setting u changed k, silently); FMPy and libcosim run such
    an FMU all the same. As for a name declared twice: the FMU loads with one warning, k and u left out, and the run
    goes on while nothing names them; a connection into u (or a value for k) is refused, naming both."""
    fmu = _fmu_with(test_fmus["CosimTGain"], tmp_path / "shared.fmu",
                    lambda s: s.replace('name="u" valueReference="1"', 'name="u" valueReference="0"'))
    alone = write_scenario(f'name: alone\ncomponents:\n  g: {{path: "{fmu}"}}\ntime: {{stop: 0.2, step: 0.01}}\n',
                           "alone.yaml")
    r = run("run", alone, "--out", tmp_path / "x.mcap", "--quiet")
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip().splitlines() == [
        "warning: shared.fmu: modelDescription.xml: k (parameter), u (input) share the Real value reference 0: left "
        "out (not logged, not settable); the run goes on while nothing names them"], r.stderr
    connected = write_scenario(SMALL.replace("{CosimTGain}", str(fmu)).replace("{k: 2.0}", "{}"), "connected.yaml")
    fails(run("run", connected, "--out", tmp_path / "y.mcap"), 2, r"connected.yaml:\d+: ",
          re.escape("shared.fmu (g): k (parameter), u (input) share the Real value reference 0: setting one would "
                    "change the other, so 'u' cannot be set or connected"))
    set_k = write_scenario(f'name: set\ncomponents:\n  g: {{path: "{fmu}", parameters: {{k: 2.0}}}}\n'
                           'time: {stop: 0.2, step: 0.01}\n', "set.yaml")
    fails(run("run", set_k, "--out", tmp_path / "z.mcap"), 2, r"set.yaml:\d+: components.g.parameters.k: ",
          "so 'k' cannot be set or connected")


def test_an_output_may_alias_an_input(run, write_scenario, test_fmus, tmp_path):
    """FMI 2.0 and 3.0 allow aliases (variables on one value reference); a set of them holds at most one parameter
    or input, and may hold outputs and locals: such an FMU loads."""
    fmu = _fmu_with(test_fmus["CosimTGain"], tmp_path / "alias.fmu",
                    lambda s: s.replace('name="u" valueReference="1"', 'name="u" valueReference="2"'))
    assert run("check", write_scenario(SMALL.replace("{CosimTGain}", str(fmu)))).returncode == 0


def test_the_fmu_as_built_still_loads(run, write_scenario, test_fmus, tmp_path):
    fmu = _fmu_with(test_fmus["CosimTGain"], tmp_path / "same.fmu", lambda s: s)
    assert run("check", write_scenario(SMALL.replace("{CosimTGain}", str(fmu)))).returncode == 0


# --------------------------------------------------------------------------- scenario files and --set values

@pytest.mark.parametrize("text, says", [
    ("", r"s.yaml:1: the file holds no scenario \(it is empty, or only comments\)"),  # two lines: every key missing
    ("# only a comment\n", r"s.yaml:1: the file holds no scenario"),
    ("name: x\x00\n", r"s.yaml:1: invalid YAML: the character U\+0000 at offset 7 is not allowed in YAML"),  # 2 lines
    ("name: x\ndescription: \"a\x1b[2J\"\n", r"s.yaml:2: invalid YAML: the character U\+001B at offset 23"),
])
def test_a_file_that_holds_no_scenario_is_one_line(run, tmp_path, text, says):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    fails(run("check", path), 2, says)


@pytest.mark.parametrize("item, says", [
    ("g.k=[]", r"--set g\.k=\[\]: k is one Real value, not a list: got a list of 0"),  # set nothing, silently
    ("g.k=[1,2]", r"--set g\.k=\[1,2\]: k is one Real value, not a list: got a list of 2"),  # one line, not two
    ("components=1", "--set components=1: name a component's parameter"),  # an IndexError traceback
])
def test_odd_set_values_are_one_line_naming_the_option(run, small, item, says):
    fails(run("check", small, "--set", item), 2, says)


def test_a_list_for_a_scalar_in_a_file_is_one_line(run, write_scenario):
    fails(run("check", write_scenario(SMALL.replace("k: 2.0", "k: [1, 2, 3]"))), 2,
          r"s.yaml:\d+: components.g.parameters.k: k is one Real value, not a list: got a list of 3")


@pytest.mark.parametrize("command", ["report", "sweep"])
def test_an_output_folder_that_is_a_file_is_one_line(run, tmp_path, small, fifo, command):
    """report --out naming a file, a FIFO or a device was a FileExistsError traceback; sweep --out too."""
    import stat

    for target in (small, fifo, Path("/dev/null")):
        args = ("report", GOLDEN, "--out", target) if command == "report" else \
            ("sweep", small, "--grid", "g.k=1", "--out", target, "--workers", "1")
        fails(run(*args), 2, f"--out {re.escape(str(target))}: is a file, not a folder")
    assert stat.S_ISFIFO(fifo.stat().st_mode) and stat.S_ISCHR(os.stat("/dev/null").st_mode)
    fails(run("report", GOLDEN, "--out", small / "sub"), 2, "cannot make the folder: .*s.yaml is a file, not a folder")


# --------------------------------------------------------------------------- forged logs for --from-log

def _forge_effective(src: Path, out: Path, data: bytes) -> Path:
    """A copy of the log ``src`` whose recorded scenario (effective/scenario.json) is ``data``."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    from cosim.engine.structure import DOCUMENT_ATTACHMENT

    with open(src, "rb") as f, open(out, "wb") as o:
        r, w = make_reader(f), Writer(o)
        w.start(profile="", library="forged")
        summary = r.get_summary()
        schemas = {s.id: w.register_schema(s.name, s.encoding, s.data) for s in summary.schemas.values()}
        channels = {c.id: w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id], dict(c.metadata))
                    for c in summary.channels.values()}
        for _, c, m in r.iter_messages():
            w.add_message(channels[c.id], m.log_time, m.data, m.publish_time)
        for a in r.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type,
                             data if a.name == DOCUMENT_ATTACHMENT else a.data)
        for md in r.iter_metadata():
            w.add_metadata(md.name, dict(md.metadata))
        w.finish()
    return out


@pytest.mark.parametrize("data, says", [
    (b"[" * 100_000 + b"]" * 100_000, "effective/scenario.json is not JSON \\(maximum recursion depth"),  # traceback
    (b'{"a": 1' + b"0" * 5000 + b"}", "effective/scenario.json is not JSON \\(Exceeds the limit"),
    (b"[1, 2]", "effective/scenario.json is not a scenario mapping"),
], ids=["deep", "digits", "list"])  # named: an id of 200 000 brackets reaches the children's environment
# (PYTEST_CURRENT_TEST) and is over the system's 128 kB for one variable: "Argument list too long"
def test_a_log_whose_recorded_scenario_is_forged_is_one_line(run, small, tmp_path, data, says):
    log = tmp_path / "log.mcap"
    assert run("run", small, "--out", log, "--quiet").returncode == 0
    forged = _forge_effective(log, tmp_path / "forged.mcap", data)
    fails(run("run", "--from-log", forged, "--out", tmp_path / "again.mcap"), 2, "forged.mcap: " + says)
    assert not list(tmp_path.glob("again.mcap*"))


def _log_with(path: Path, effective: bytes, before: bytes = b"", ssp: dict | None = None) -> Path:
    """A log holding, in this order, an attachment of ``before`` (if any), the ``ssp`` metadata (if any) and the
    recorded scenario ``effective``: what ``run --from-log`` reads before it stops."""
    from mcap.writer import Writer

    from cosim.engine.structure import DOCUMENT_ATTACHMENT

    with open(path, "wb") as o:
        w = Writer(o)
        w.start(profile="", library="forged")
        if before:
            w.add_attachment(0, 0, "big.bin", "application/octet-stream", before)
        if ssp is not None:
            w.add_metadata("ssp", ssp)
        w.add_attachment(0, 0, DOCUMENT_ATTACHMENT, "application/json", effective)
        w.finish()
    return path


def test_what_run_from_log_reads_of_a_log_is_bounded(run, small, tmp_path):
    """A log's attachment of gigabytes before the recorded scenario was read whole; a recorded scenario of millions
    of values took gigabytes where a scenario file is refused; a log naming a huge (sparse) SSP archive had it
    hashed for minutes. Each is one line, at once."""
    log = tmp_path / "log.mcap"
    assert run("run", small, "--out", log, "--quiet").returncode == 0
    from cosim.io.runlog import read_run

    effective = read_run(log).attachments["effective/scenario.json"]
    big = _log_with(tmp_path / "big.mcap", effective, before=b"\0" * (20 * 2 ** 20))
    fails(run("run", "--from-log", big, "--out", tmp_path / "a.mcap"), 2,
          "big.mcap: a record before the scenario as run is larger than 17,825,792 bytes")
    many = _log_with(tmp_path / "many.mcap", b'{"x": [' + b"0," * 300_000 + b"0]}")
    fails(run("run", "--from-log", many, "--out", tmp_path / "b.mcap"), 2,
          "many.mcap: effective/scenario.json holds 600,010 bytes, about 300,002 values: more than a scenario may")
    sparse = tmp_path / "huge.ssp"
    with open(sparse, "wb") as f:
        f.truncate(17 * 1024 ** 3)  # a hole: no disk used, 17 GiB to read
    named = _log_with(tmp_path / "named.mcap", effective,
                      ssp={"file": str(sparse), "sha256": "0" * 64, "unpacked": str(tmp_path / "gone")})
    fails(run("run", "--from-log", named, "--out", tmp_path / "c.mcap"), 2,
          f"the run was made from the SSP archive {sparse}, which is 18,253,611,008 bytes, more than any archive")
    assert not list(tmp_path.glob("[abc].mcap*"))


# --------------------------------------------------------------------------- logs cut anywhere

@pytest.mark.parametrize("keep", [1000, -10, -1])
@pytest.mark.parametrize("command", ["table", "report", "compare", "baseline"])
def test_a_log_cut_inside_a_record_is_one_line_for_every_reader(run, tmp_path, keep, command):
    """A log cut 1000 bytes in, or 10 or 1 byte short of its end: the mcap reader's struct.error was a traceback in
    table, report, compare and baseline (the cut at half the file, tested in test_faults, fell on a record's end)."""
    data = GOLDEN.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:keep] if keep > 0 else data[:len(data) + keep])
    args = {"table": ("table", cut), "report": ("report", cut, "--out", tmp_path / "rep"),
            "compare": ("compare", cut, GOLDEN), "baseline": ("baseline", cut, "--out", tmp_path / "b.mcap")}[command]
    fails(run(*args), 2, "cut.mcap: cannot read the MCAP log", "recover")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cut.mcap", "tmp"], sorted(tmp_path.iterdir())


@pytest.mark.parametrize("args, says", [
    (("run", "{S}", "--watchdog", "-1", "--json"), "argument --watchdog: expected a finite number >= 0, got '-1'"),
    (("robot", "ik", "--robot", "linear_delta_thesis", "--json", "0", "0", "nan"), "argument Z: expected a finite"),
    (("run", "{S}", "--outt", "x.mcap", "--json"), "unrecognized arguments: --outt x.mcap"),
])
def test_with_json_a_usage_error_is_a_json_object_too(run, small, args, says):
    """--json promises a JSON object on stdout whatever happens; a bad option value (now argparse's error, as every
    numeric option's) printed nothing there."""
    import json

    r = run(*[str(small) if a == "{S}" else a for a in args])
    fails(r, 2, says, usage=True)
    error = json.loads(r.stdout)
    assert error["ok"] is False and error["kind"] == "usage" and says in error["error"], error


def test_an_internal_error_is_one_line_naming_it_not_a_component_exit(capsys, monkeypatch):
    """A defect an input reaches (the exceptions above were such): one line with the exception and where it was
    raised, exit 2 (it was the interpreter's traceback, which the supervisor then reported as 'exited with status 1
    (an exit() inside a component)')."""
    from cosim.__main__ import _internal_error

    monkeypatch.delenv("COSIM_TRACEBACK", raising=False)
    try:
        {}["missing"]
    except KeyError as exc:
        code = _internal_error(exc)
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith("error: internal error (KeyError: 'missing') at test_hostile_more.py:"), err
