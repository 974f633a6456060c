"""Recover an unfinished MCAP log (killed writer, full disk): stream-read every complete record, rewrite indexed."""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from pathlib import Path

from ..errors import CosimError, file_problem, written_by_rename
from .output import check_output
from .runlog import log_records

__all__ = ["recover", "recover_crashed", "RecoveryReport", "NothingLogged"]


@dataclass(frozen=True)
class RecoveryReport:
    out: str
    messages: int
    channels: int
    attachments: int
    metadata: int
    truncated: bool  # the input ended inside a record (the usual case for a killed writer)

    def as_dict(self) -> dict:
        return asdict(self)


class NothingLogged(CosimError):
    """The file holds no complete record: there is nothing to recover (a run that died before its log began)."""


def recover(path: str | Path, out: str | Path | None = None) -> RecoveryReport:
    """Copy every complete schema, channel, message, attachment and metadata record into a new file.

    The copy is written under a temporary name next to ``out`` and renamed when complete: a
    failure (disk full) leaves no output, not an empty or truncated one.
    """

    path = Path(path)
    out = Path(out) if out else _default_out(path)
    problem = file_problem(path)
    if problem is not None:
        # Refused (security): a FIFO or a device named as a log would be read for ever
        raise CosimError(f"{path}: {problem}")
    check_output(out, (path,))
    try:
        with written_by_rename(out) as tmp:
            report = _copy(path, tmp, out)
    except OSError as exc:
        # Refused (correctness): the copy could not be written whole: nothing is left half-written
        raise CosimError(f"{out}: cannot write the recovered log: {exc.strerror or exc}; nothing was written "
                         f"({path} is unchanged)") from None
    return report


def recover_crashed(info: dict) -> tuple[str | None, str | None]:
    """The log of a run whose process died (the description its supervisor's record holds,
    :meth:`cosim.engine.supervision.Record.info`: ``partial``, ``target``): recovered into its target, the partial
    file and the claim's lock removed. Returns (the recovered log or None, one line saying where the log is; None
    without a log)."""
    partial, target = info.get("partial"), info.get("target")
    if not partial or not Path(partial).exists():
        return None, None
    try:
        report = recover(partial, target)
    except NothingLogged:  # died before its log's first record (a crash in initialization): nothing is lost
        Path(partial).unlink(missing_ok=True)  # kept, it blocked the next run on that output and recover refused it
        return None, "no log: the run ended before its first record was written"
    except CosimError as exc:
        return None, f"the log written so far stays in {partial} ({exc}): `python -m cosim recover {partial}`"
    finally:
        if target:
            Path(target + ".lock").unlink(missing_ok=True)
    Path(partial).unlink(missing_ok=True)
    return report.out, f"the log up to the crash ({report.messages} messages) is in {report.out}"


def _default_out(path: Path) -> Path:
    """``X.mcap`` and ``X.mcap.partial`` -> ``X.recovered.mcap``."""
    name = path.name.removesuffix(".partial").removesuffix(".mcap")
    return path.with_name(name + ".recovered.mcap")


def _copy(path: Path, tmp: Path, out: Path) -> RecoveryReport:
    from mcap.exceptions import McapError  # lazy: --help loads this module without it
    from mcap.records import (  # lazy: --help loads this module without it
        Attachment,
        Channel,
        Message,
        Metadata,
        Schema,
    )
    from mcap.writer import (  # lazy: --help loads this module without it
        CompressionType,
        Writer,
    )


    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    counts = {"messages": 0, "attachments": 0, "metadata": 0}
    truncated = False
    with open(path, "rb") as src, open(tmp, "wb") as dst:
        w = Writer(dst, compression=CompressionType.ZSTD)
        w.start(profile="", library="cosim-recover")

        def handle(rec) -> None:
            if isinstance(rec, Schema) and rec.id not in schemas and rec.id != 0:
                schemas[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel) and rec.id not in channels:
                channels[rec.id] = w.register_channel(rec.topic, rec.message_encoding, schemas.get(rec.schema_id, 0),
                                                      rec.metadata)
            elif isinstance(rec, Message) and rec.channel_id in channels:
                w.add_message(channels[rec.channel_id], rec.log_time, rec.data, rec.publish_time, rec.sequence)
                counts["messages"] += 1
            elif isinstance(rec, Attachment):
                w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
                counts["attachments"] += 1
            elif isinstance(rec, Metadata):
                w.add_metadata(rec.name, rec.metadata)
                counts["metadata"] += 1

        try:
            for rec in log_records(src, path):  # a chunk past runlog.MAX_CHUNK_BYTES: CosimError, nothing written
                handle(rec)
        except CosimError:
            raise
        except OSError as exc:
            if exc.errno is not None:  # a real I/O failure (reading, or writing: disk full), not a short input
                raise
            truncated = True
        except (McapError, EOFError, ValueError, Exception):  # noqa: B014 - any damage ends the usable input
            truncated = True
        if truncated and not (schemas or channels or any(counts.values())):
            # Refused (correctness): nothing of a run to keep: an empty copy would look like a log
            raise NothingLogged(f"{path}: not an MCAP log (no complete record in it); nothing was written")
        if truncated:
            w.add_metadata("recovery", {"source": str(path), "note": "input ended inside a record; "
                                                                     "complete records kept"})
        w.finish()
        dst.flush()
        os.fsync(dst.fileno())
    return RecoveryReport(str(out), counts["messages"], len(channels), counts["attachments"], counts["metadata"],
                          truncated)
