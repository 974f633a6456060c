"""An SSP archive's members as the reader takes them: where a relative reference points (never outside the archive),
a member's bytes (bounded, whatever its header claims), its XML (with libcosim's one repair), and a component's FMU
as the run will read it."""

from __future__ import annotations

import posixpath
import re
import zipfile
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlparse
from xml.etree import ElementTree as ET

from ...errors import CosimError
from ...fmi.description import FMUInfo, load_fmu
from .spec import NS, SspError

__all__ = ["MAX_XML_BYTES", "component_fmu", "member_path", "parse_xml", "read_member"]


_ROOT_TAG = re.compile(rb"<[A-Za-z_][\w.:-]*")  # the first start tag (not <?xml, <!-- or <!DOCTYPE)


def parse_xml(data: bytes, ssp: Path, member: str) -> ET.Element:
    """A member's XML. One repair, as libcosim makes it: published OSP files use the ``osp:`` prefix of their
    annotations without declaring it (an unbound prefix, not well-formed XML); it gets OSP's namespace."""
    try:
        return ET.fromstring(data)
    except ET.ParseError as exc:
        if "unbound prefix" in str(exc) and b"<osp:" in data and b"xmlns:osp" not in data:
            declared = _ROOT_TAG.sub(lambda m: m.group(0) + f' xmlns:osp="{NS["osp"]}"'.encode(), data, count=1)
            try:
                return ET.fromstring(declared)
            except ET.ParseError:
                pass
        # Refused (correctness): what the member means cannot be read
        raise SspError(ssp, f"{member}: not well-formed XML ({exc})") from None


MAX_XML_BYTES = 64 * 1024 * 1024
"""Largest .ssd or .ssv an archive may unpack to (ours are a few kB; a zip bomb inflated one to 2.5 GiB)."""


def read_member(zf: zipfile.ZipFile, member: str, ssp: Path) -> bytes:
    """An XML member of the archive, read no further than :data:`MAX_XML_BYTES` (whatever its header claims)."""
    with zf.open(member) as f:
        data = f.read(MAX_XML_BYTES + 1)
    if len(data) > MAX_XML_BYTES:
        # Refused (security): a zip bomb: read no further than the bound
        raise SspError(ssp, f"{member} unpacks to more than {MAX_XML_BYTES:,} bytes: refused")
    return data


def member_path(base: str, uri: str, ssp: Path, what: str) -> str:
    """The archive member a relative URI in ``base`` (a member's directory) points at."""
    parsed = urlparse(uri)
    if parsed.scheme or parsed.netloc or uri.startswith("/"):
        # Refused (security): a URL or an absolute path would read outside the archive
        raise SspError(ssp, f"{what}: source {uri!r} is not a relative reference into the archive "
                            "(only those are supported)")
    path = posixpath.normpath(posixpath.join(base, unquote(parsed.path)))
    if path.startswith("../") or path == "..":
        # Refused (security): a path out of the archive (../) would read the user's files
        raise SspError(ssp, f"{what}: source {uri!r} points outside the archive")
    return path


def component_fmu(comp: str, components: dict[str, dict[str, Any]], ssp: Path) -> FMUInfo:
    """A component's FMU as the run will read it (:func:`cosim.fmi.load_fmu`: checked, read once per file and
    process, so the run's own preparation reuses it)."""
    try:
        return load_fmu(components[comp]["path"])
    except CosimError as exc:
        # Refused (correctness): an FMU the run cannot read (the error of load_fmu, named by component)
        raise SspError(ssp, f"component {comp!r}: {exc}") from None
