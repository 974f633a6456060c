"""Build the tiny pythonfmu test FMUs (once per session) and patch their ModelStructure.

pythonfmu leaves output dependencies undeclared; the master then assumes every
output depends on every input. The patch declares the real dependencies, so the
tests exercise the declared-feedthrough path: the gain and the raiser feed
through (y depends on u), the integrator, source and slow ramp do not.
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

SOURCES = Path(__file__).parent / "fmu_sources"
# FMU name -> {output: [inputs it depends on directly]}
DEPENDENCIES = {
    "CosimTSource": {"y": []},
    "CosimTGain": {"y": ["u"]},
    "CosimTIntegrator": {"x": []},
    "CosimTRaiser": {"y": ["u"]},
    "CosimTSlow": {"y": []},
    "CosimTSum": {"y": ["a", "b"], "n": []},
    "CosimTCrash": {"y": []},
}
SCRIPTS = {
    "CosimTSource": "cosim_t_source.py",
    "CosimTGain": "cosim_t_gain.py",
    "CosimTIntegrator": "cosim_t_integrator.py",
    "CosimTRaiser": "cosim_t_raiser.py",
    "CosimTSlow": "cosim_t_slow.py",
    "CosimTSum": "cosim_t_sum.py",
    "CosimTCrash": "cosim_t_crash.py",
}


def _declare_dependencies(fmu: Path, deps: dict[str, list[str]], undeclared: bool = False) -> None:
    with zipfile.ZipFile(fmu) as z:
        items = {n: z.read(n) for n in z.namelist()}
    xml = items["modelDescription.xml"].decode()
    names = re.findall(r'<ScalarVariable[^>]*name="([^"]+)"', xml)
    index = {n: i + 1 for i, n in enumerate(names)}

    def patch(m: re.Match) -> str:
        i = int(m.group(1))
        out = names[i - 1]
        d = " ".join(str(index[u]) for u in deps.get(out, []))
        return m.group(0) if undeclared else f'<Unknown index="{i}" dependencies="{d}"'

    xml = re.sub(r'<Unknown index="(\d+)"', patch, xml)
    items["modelDescription.xml"] = xml.encode()
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in items.items():
            z.writestr(n, data)


def build_test_fmus(dest: Path) -> dict[str, Path]:
    """Build every test FMU into ``dest``; returns model name -> .fmu path."""
    from pythonfmu.builder import FmuBuilder

    dest.mkdir(parents=True, exist_ok=True)
    out = {}
    for model, script in SCRIPTS.items():
        path = Path(FmuBuilder.build_FMU(SOURCES / script, dest=dest))
        _declare_dependencies(path, DEPENDENCIES[model])
        out[model] = path
    # the same gain with pythonfmu's undeclared dependencies, for the "assumed feedthrough" path
    raw = dest / "CosimTGainUndeclared.fmu"
    raw.write_bytes(out["CosimTGain"].read_bytes())
    with zipfile.ZipFile(raw) as z:
        items = {n: z.read(n) for n in z.namelist()}
    xml = re.sub(r' dependencies="[^"]*"', "", items["modelDescription.xml"].decode())
    items["modelDescription.xml"] = xml.encode()
    with zipfile.ZipFile(raw, "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in items.items():
            z.writestr(n, data)
    out["CosimTGainUndeclared"] = raw
    return out


if __name__ == "__main__":
    import sys

    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent / "scenarios" / "fmus"
    for name, path in build_test_fmus(target).items():
        print(f"{name}: {path}")


# A slow feed-forward pair for interruption, watchdog and concurrency tests: the ramp sleeps
# ``delay`` s per step (``{CosimTSlow}`` / ``{CosimTGain}`` are replaced by the built FMUs' paths).
SLOW_SCENARIO = """
name: slow
components:
  ramp: {path: "{CosimTSlow}", parameters: {delay: 0.002}}
  g: {path: "{CosimTGain}"}
connections:
  - {from: ramp.y, to: g.u}
time: {stop: 20.0, step: 0.01}
logging: {flush_interval: 0.1}
"""


_LIVE_LOGGER: list = []  # fmpy's default logger as a ctypes thunk that lives as long as the process, and its struct


def repoint_fmpy_logger() -> None:
    """Point fmpy's C logging proxy at fmpy's default logger, through a thunk that lives as long as the process.

    The proxy (``fmpy/logging``: ``addLoggerProxy``) keeps ONE logger for the whole process, a C global set by the
    last ``addLoggerProxy`` call. ``fmpy.simulate_fmu(..., logger=f)`` sets it to a ctypes thunk of ``f`` that is
    freed when ``simulate_fmu`` returns, so the next FMU in the process that logs through the proxy (any FMU fmpy
    instantiates with its default callbacks) calls freed memory: measured, a later Horizon model-exchange run's log
    calls landed in CVode's right-hand-side thunk (``Exception ignored on calling ctypes callback function:
    CVodeSolver.f``), and once a CI worker segfaulted in ``fmi2SetTime`` and xdist waited for it until the stall
    guard stopped the suite. Our master is not exposed (its slaves give the proxy one thunk that lives as long as
    the process, ``cosim.fmi.logger.fmi2_logger``); tests that call ``simulate_fmu`` with a logger are (the suite
    calls this after every test: ``tests/conftest.py``)."""
    from ctypes import byref

    from fmpy.fmi1 import printLogMessage
    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    from fmpy.logging import addLoggerProxy

    if not _LIVE_LOGGER:
        _LIVE_LOGGER.extend((fmi2CallbackLoggerTYPE(printLogMessage), fmi2CallbackFunctions()))
    thunk, callbacks = _LIVE_LOGGER
    callbacks.logger = thunk  # the proxy put itself in the struct last time, and skips a struct that holds it
    addLoggerProxy(byref(callbacks))
