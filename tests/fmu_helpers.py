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
