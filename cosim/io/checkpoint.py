"""Checkpoint files: a whole co-simulation's state at one time, written by ``run --checkpoint-at`` and continued by
``run --resume`` (as libcosim's ``export_current_state`` / ``import_state`` of an execution, with the scenario inside).

A checkpoint is a zip archive (each member with its CRC, so damage is found, never read as a state):

- ``checkpoint.json``: format and version; the time (``t_ns``, the macro steps done), the time grid and algorithm;
  per component its name, the FMU's guid (instantiation token) and the SHA-256 of its file, the time it reached,
  the master's copies of its exchanged values by variable (``in:NAME`` / ``out:NAME``) and the wrapper's bookkeeping, the name, size and SHA-256 of its
  serialized FMU state; the events' progress (time events fired, state events armed); the command that wrote it;
- ``scenario.json``: the scenario as it ran (every override applied, FMU paths absolute);
- ``states/<i>.bin``: component ``i``'s FMU state as the FMU serialized it (``fmi2SerializeFMUstate``).

Nothing but plain data is read from it: the FMU states go back to the FMUs, which check them themselves.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..engine.execution import Execution, SystemState
from ..errors import CosimError, written_by_rename

__all__ = ["FORMAT", "VERSION", "CheckpointError", "Checkpoint", "write_checkpoint", "read_checkpoint",
           "file_sha256", "default_checkpoint_path"]

FORMAT = "delta-cosim checkpoint"
VERSION = 1
_MAX_MEMBER = 64 << 20
"""Bytes a checkpoint member may hold, read into memory: zipfile reads no more than a member declares, and a
member declaring more is refused unread. An Exudyn plant's state is about 30 kB, a header a few kB per component."""


class CheckpointError(CosimError, ValueError):
    """A checkpoint that cannot be written, read or continued (damaged, of another scenario or FMU build, a time
    outside the run)."""


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def default_checkpoint_path(log: str | Path | None, scenario_name: str) -> Path:
    """Beside the log, with the suffix ``.ckpt`` (``runs/helix_ctc.mcap`` -> ``runs/helix_ctc.ckpt``); without a log,
    ``runs/<scenario>.ckpt``."""
    if log is not None:
        return Path(os.path.normpath(Path(log).with_suffix(".ckpt")))
    return Path("runs") / f"{scenario_name}.ckpt"


@dataclass
class Checkpoint:
    """A checkpoint read back: its header (``checkpoint.json``), the scenario as run, the components' FMU states."""

    path: Path
    header: dict
    scenario: dict
    states: list[bytes]

    @property
    def t_ns(self) -> int:
        return int(self.header["t_ns"])

    @property
    def time(self) -> float:
        return self.t_ns * 1e-9

    @property
    def k_done(self) -> int:
        return int(self.header["k_done"])

    @property
    def archive(self) -> dict[str, str] | None:
        """The SSP archive the run was read from (``file``, ``sha256``, ``unpacked``), None for a YAML scenario's."""
        return self.header.get("ssp")

    def component(self, name: str) -> dict:
        for c in self.header["components"]:
            if c["name"] == name:
                return c
        # Refused (correctness): a component without its state would start from t = 0 beside the others
        raise CheckpointError(f"{self.path}: no state of component {name!r} (it holds "
                              f"{', '.join(c['name'] for c in self.header['components'])})")

    def check_system(self, ex: Execution, scenario_name: str) -> None:
        """The system to continue is the one that wrote this checkpoint: the same components, each on the same FMU
        (guid and file), the same time grid and algorithm; raises :class:`CheckpointError` naming what differs."""
        h = self.header
        names = [c["name"] for c in h["components"]]
        if names != list(ex.plan.names):
            # Refused (correctness): states set into other components: a checkpoint of another scenario
            raise CheckpointError(f"{self.path} holds the components {', '.join(names)}; scenario {scenario_name!r} "
                                  f"has {', '.join(ex.plan.names)}: a checkpoint of another scenario")
        if (h["grid"]["start_ns"], h["grid"]["step_ns"]) != (ex.start_ns, ex.step_ns):
            # Refused (correctness): the resumed run would step on another grid than the one saved
            raise CheckpointError(f"{self.path} was written on a time grid from {h['grid']['start_ns'] * 1e-9:g} s "
                                  f"in steps of {h['grid']['step_ns'] * 1e-9:g} s; this run's starts at "
                                  f"{ex.start_ns * 1e-9:g} s in steps of {ex.step_ns * 1e-9:g} s")
        if h["algorithm"] != ex.algorithm_name:
            # Refused (correctness): another algorithm exchanges other values: the resumed run would differ
            raise CheckpointError(f"{self.path} was written by the {h['algorithm']} algorithm; this run uses "
                                  f"{ex.algorithm_name}")
        if not self.t_ns < ex.stop_ns:
            # Refused (correctness): nothing to continue: the run would be empty
            raise CheckpointError(f"{self.path} is at t = {self.time:g} s, not before this run's stop time "
                                  f"{ex.stop_ns * 1e-9:g} s: nothing to continue (give a later --stop-time)")
        if ex.grid.t_ns(self.k_done) != self.t_ns:
            # Refused (correctness): the resumed steps would fall off this run's grid
            raise CheckpointError(f"{self.path}: t = {self.time:g} s is not the end of macro step {self.k_done} of "
                                  "this run's grid")
        for c, (entry, info) in enumerate(zip(h["components"], ex.plan.infos)):
            guid = info.md.guid
            if entry["guid"] != guid:
                # Refused (correctness): a state set into another FMU (only the FMU that wrote a state reads it)
                raise CheckpointError(f"{self.path}: component {entry['name']!r} was saved from the FMU with guid "
                                      f"{entry['guid']}; this run's {info.path.name} has guid {guid}: a checkpoint "
                                      "of another FMU build")
            digest = file_sha256(info.path)
            if entry["fmu_sha256"] != digest:
                # Refused (correctness): same guid, other bytes: another build, its state may mean another thing
                raise CheckpointError(f"{self.path}: component {entry['name']!r} was saved from an FMU file with "
                                      f"SHA-256 {entry['fmu_sha256'][:16]}...; {info.path} has {digest[:16]}...: "
                                      "a checkpoint of another FMU build")

    def restore_into(self, ex: Execution) -> SystemState:
        """The saved state imported into ``ex``'s initialized components and restored (the FMUs check their own
        states); returns it (the caller frees it)."""
        comps = []
        for c, (entry, slave) in enumerate(zip(self.header["components"], ex.slaves)):
            ex.current[0] = c
            buffers = entry["decoded"]
            slave.time = float(entry["time"])  # an FMU refusing the state is named at the checkpoint's time
            comps.append(slave.import_state(self.states[c], float(entry["time"]), buffers, entry["extra"]))
        state = SystemState(self.k_done, comps)
        ex.restore_state(state)
        return state


def write_checkpoint(path: str | Path, ex: Execution, scenario: dict, command: str = "",
                     ssp: dict[str, str] | None = None) -> int:
    """Write ``ex``'s state now (after macro step ``ex.k_done``) to ``path`` (whole or not at all); returns its
    size in bytes. ``scenario``: the scenario as run (:func:`cosim.engine.scenario.effective_scenario`); ``ssp``: the
    SSP archive the system was read from (:attr:`cosim.engine.structure.SystemStructure.ssp`: its FMUs, unpacked for
    that run only, are unpacked again from it to resume)."""
    missing = [n for n, s in zip(ex.plan.names, ex.slaves) if not getattr(s, "can_serialize_state", False)]
    if missing:
        # Refused (correctness): a checkpoint without those states could not resume the run
        raise CheckpointError(f"cannot write a checkpoint: the state of {', '.join(missing)} cannot be serialized "
                              "(no canSerializeFMUstate in its FMU)")
    state = ex.save_state()
    try:
        blobs = [s.export_state(cs) for s, cs in zip(ex.slaves, state.components)]
    finally:
        ex.free_state(state)
    ex.restart_integrators()  # a model-exchange integrator re-starts here, as it will in the resumed run
    components = []
    for c, (name, info, cs, blob) in enumerate(zip(ex.plan.names, ex.plan.infos, state.components, blobs)):
        components.append({
            "name": name, "fmu": info.path.name, "guid": info.md.guid, "fmu_sha256": file_sha256(info.path),
            "fmi": info.fmi_major, "time": cs.time,
            "exchanged": {k: _encode_buffer(v) for k, v in ex.slaves[c].exchanged(cs).items()}, "extra": cs.extra,
            "state": f"states/{c}.bin", "state_bytes": len(blob), "state_sha256": hashlib.sha256(blob).hexdigest(),
        })
    ev = ex.events
    header = {
        "format": FORMAT, "version": VERSION, "scenario": scenario.get("name"), "t_ns": ex.t_ns(ex.k_done),
        "k_done": ex.k_done, "grid": {"start_ns": ex.start_ns, "stop_ns": ex.stop_ns, "step_ns": ex.step_ns},
        "algorithm": ex.algorithm_name, "components": components, "command": command,
        "events": None if ev is None else ev.progress(),
    }
    if ssp is not None:
        header["ssp"] = dict(ssp)
    path = Path(path)
    with written_by_rename(path) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
            z.writestr("checkpoint.json", json.dumps(header, indent=1, allow_nan=True))
            z.writestr("scenario.json", json.dumps(scenario, indent=1, allow_nan=True))
            for entry, blob in zip(components, blobs):
                z.writestr(entry["state"], blob)
        size = tmp.stat().st_size
    return size


def read_checkpoint(path: str | Path) -> Checkpoint:
    """Read and verify a checkpoint (format, version, every member's CRC and SHA-256); raises
    :class:`CheckpointError` naming the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        # Refused (correctness): no checkpoint, nothing to resume
        raise CheckpointError(f"{path}: no such checkpoint file")
    try:
        with zipfile.ZipFile(path) as z:
            def member(name: str) -> bytes:
                try:
                    info = z.getinfo(name)
                except KeyError:
                    # Refused (correctness): a part of the checkpoint is missing
                    raise CheckpointError(f"{path}: not a complete checkpoint (no {name})") from None
                if info.file_size > _MAX_MEMBER:
                    # Refused (security): a zip bomb: a member is bounded before it is read
                    raise CheckpointError(f"{path}: {name} claims {info.file_size} bytes; refused")
                return z.read(name)

            header = _json(path, "checkpoint.json", member("checkpoint.json"))
            if header.get("format") != FORMAT:
                # Refused (correctness): another format: its values would mean other things
                raise CheckpointError(f"{path}: not a delta-cosim checkpoint")
            if header.get("version") != VERSION:
                # Refused (correctness): another version's layout: its values would mean other things
                raise CheckpointError(f"{path}: checkpoint format version {header.get('version')!r}; this version "
                                      f"of delta-cosim reads version {VERSION}")
            scenario = _json(path, "scenario.json", member("scenario.json"))
            _check_header(path, header)
            states = []
            for entry in header["components"]:
                blob = member(entry["state"])
                if len(blob) != entry["state_bytes"] or hashlib.sha256(blob).hexdigest() != entry["state_sha256"]:
                    # Refused (correctness): a state that does not match its checksum would be set as it is
                    raise CheckpointError(f"{path}: the state of component {entry['name']!r} is damaged "
                                          f"({len(blob)} bytes, its checksum does not match)")
                states.append(blob)
    except CheckpointError:
        raise
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, KeyError, TypeError, ValueError) as exc:
        # Refused (correctness): a damaged checkpoint: what it holds cannot be read whole
        raise CheckpointError(f"{path}: not a checkpoint, or a damaged or truncated one ({type(exc).__name__}: "
                              f"{exc})") from None
    return Checkpoint(path, header, scenario, states)


_HEADER = {"t_ns": int, "k_done": int, "grid": dict, "algorithm": str, "components": list}
_COMPONENT = {"name": str, "guid": str, "fmu_sha256": str, "time": (int, float), "exchanged": dict, "extra": dict,
              "state": str, "state_bytes": int, "state_sha256": str}


def _check_header(path: Path, header: dict) -> None:
    """Every key of ``checkpoint.json`` present with its type, and the exchanged values decoded (into each
    component's ``decoded``); raises CheckpointError naming the first key that is not."""
    def bad(what: str) -> CheckpointError:
        return CheckpointError(f"{path}: checkpoint.json is malformed ({what})")

    for key, kind in _HEADER.items():
        if not isinstance(header.get(key), kind) or isinstance(header.get(key), bool):
            # Refused (correctness): a header of the wrong shape: what it holds cannot be read
            raise bad(f"{key} missing or not a {kind.__name__}")
    for key in ("start_ns", "stop_ns", "step_ns"):
        if not isinstance(header["grid"].get(key), int):
            # Refused (correctness): a header of the wrong shape: what it holds cannot be read
            raise bad(f"grid.{key} missing or not an integer")
    ssp = header.get("ssp")
    if ssp is not None and not (isinstance(ssp, dict) and all(isinstance(ssp.get(k), str)
                                                              for k in ("file", "sha256", "unpacked"))):
        # Refused (correctness): the archive whose FMUs the run used cannot be found again
        raise bad("ssp is not an object of file, sha256 and unpacked")
    for i, entry in enumerate(header["components"]):
        if not isinstance(entry, dict):
            # Refused (correctness): a header of the wrong shape: what it holds cannot be read
            raise bad(f"components[{i}] is not an object")
        for key, kind in _COMPONENT.items():
            if not isinstance(entry.get(key), kind):
                # Refused (correctness): a header of the wrong shape: what it holds cannot be read
                raise bad(f"components[{i}].{key} missing or of the wrong type")
        try:
            entry["decoded"] = {k: _decode_buffer(v) for k, v in entry["exchanged"].items()}
        except (TypeError, ValueError, KeyError, AttributeError):
            # Refused (correctness): the exchanged values cannot be read: the first resumed step would be wrong
            raise bad(f"components[{i}].exchanged does not decode") from None


def _encode_buffer(values: bytes | list) -> Any:
    """A buffer snapshot as JSON: the bytes of a numeric buffer as hex; a String buffer as its list; a Binary
    buffer (a list of bytes) as ``{"binary": [hex, ...]}``."""
    if isinstance(values, bytes):
        return values.hex()
    if any(isinstance(v, (bytes, bytearray)) for v in values):
        return {"binary": [bytes(v).hex() for v in values]}
    return list(values)


def _decode_buffer(data: Any) -> bytes | list:
    if isinstance(data, str):
        return bytes.fromhex(data)
    if isinstance(data, dict):
        return [bytes.fromhex(v) for v in data["binary"]]
    return list(data)


def _json(path: Path, name: str, data: bytes) -> Any:
    try:
        value = json.loads(data)
    except (UnicodeDecodeError, ValueError) as exc:
        # Refused (correctness): the checkpoint's description cannot be read
        raise CheckpointError(f"{path}: {name} is not valid JSON ({exc})") from None
    if not isinstance(value, dict):
        # Refused (correctness): the checkpoint's description cannot be read
        raise CheckpointError(f"{path}: {name} is not a JSON object")
    return value
