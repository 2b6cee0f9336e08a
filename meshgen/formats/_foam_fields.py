"""The starting fields of an OpenFOAM case (``0/U`` and ``0/p`` for potential flow) and which of
them a re-mesh may rewrite.

meshgen records in ``constant/polyMesh/meshgen.json`` (key ``fields``), for each field it wrote,
the SHA-256 of the text and its boundary entries (patch -> {keyword: value}, ``value`` left out).
When the same case is meshed again, each field is:

- written when it is missing (deleting a field resets it);
- rewritten for the new mesh when it is meshgen's: its text is the one recorded, or a solver
  (potentialFoam) has rewritten it - its header is no longer meshgen's and its boundary entries,
  ``value`` aside, are still the recorded ones (a solver replaces the internal field and the
  ``value`` entries, which belong to the old mesh and would stop the next run);
- kept otherwise (a user's edit, or a field meshgen has no record of), and named in one warning
  line that says how to reset it.

Fields meshgen never writes (``phi``, a user's ``k``) are left as they are.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

from meshgen.geometry.patches import flow_role

__all__ = [
    "FIELD_NAMES",
    "MESHGEN_BANNER",
    "boundary_entries",
    "field_record",
    "fields_to_write",
    "kept_warning",
    "previous_fields",
    "starting_fields",
]

FIELD_NAMES = ("U", "p")
MESHGEN_BANNER = "Written by meshgen"
DIMENSIONS = {"U": "[0 1 -1 0 0 0 0]", "p": "[0 2 -2 0 0 0 0]"}
INTERNAL = {"U": "(0 0 0)", "p": "0"}
CLASS_NAMES = {"U": "volVectorField", "p": "volScalarField"}
HEAD_BYTES = 4096  # the FoamFile header and the banner above it
TAIL_BYTES = 64 * 2**20  # a field larger than this is parsed from its head and its last TAIL_BYTES


def starting_fields(patches, header) -> dict[str, str]:
    """{"U": text, "p": text}: potential flow from the patches' types and roles (1 m/s into the
    domain normal to the inlet, p = 0 on the outlet, slip walls, symmetry, empty and cyclic as
    their types, zero gradient elsewhere). ``header(class_name, location, object_name)`` gives the
    FoamFile header."""
    U, p = {}, {}
    for patch in patches:
        role = flow_role(patch)
        if role == "inflow":
            U[patch.name], p[patch.name] = "type surfaceNormalFixedValue; refValue uniform -1;", "type zeroGradient;"
        elif role == "outflow":
            U[patch.name], p[patch.name] = "type zeroGradient;", "type fixedValue; value uniform 0;"
        elif patch.type == "wall":
            U[patch.name], p[patch.name] = "type slip;", "type zeroGradient;"
        elif patch.type in ("symmetry", "empty", "cyclic"):
            U[patch.name] = p[patch.name] = f"type {patch.type};"
        else:
            U[patch.name], p[patch.name] = "type zeroGradient;", "type zeroGradient;"
    texts = {}
    for name, entries in (("U", U), ("p", p)):
        body = "".join(f"    {patch}\n    {{\n        {entry}\n    }}\n" for patch, entry in entries.items())
        texts[name] = header(CLASS_NAMES[name], "0", name) + (
            f"dimensions      {DIMENSIONS[name]};\n\ninternalField   uniform {INTERNAL[name]};\n\nboundaryField\n{{\n{body}}}\n"
        )
    return texts


def boundary_entries(text: str) -> dict[str, dict[str, str]] | None:
    """patch -> {keyword: value} of a field's ``boundaryField`` (whitespace collapsed, ``value``
    left out: a solver writes it for the mesh it ran on); None when there is no boundaryField."""
    start = text.find("boundaryField")
    if start < 0:
        return None
    entries = {}
    for patch, body in re.findall(r"([^\s{}();]+)\s*\{([^{}]*)\}", text[start + len("boundaryField") :]):
        items = {}
        for key, value in re.findall(r"(\w+)\s+([^;]*);", body):
            if key != "value":
                items[key] = " ".join(value.split())
        entries[patch] = items
    return entries


def field_record(texts: dict[str, str]) -> dict:
    """What ``meshgen.json`` records of the fields written: {name: {"sha256", "boundary"}}."""
    return {name: {"sha256": _digest(text), "boundary": boundary_entries(text)} for name, text in texts.items()}


def fields_to_write(folder: Path, texts: dict[str, str], previous: dict) -> tuple[dict[str, str], list[str]]:
    """(the fields of ``texts`` to write into ``folder`` (``CASE/0``), the names of those kept):
    missing fields and meshgen's own (its recorded text, or that text solved by a solver) are
    written; any other existing field is kept. ``previous``: the ``fields`` record of the case's
    last meshgen.json ({} if none)."""
    write, kept = {}, []
    for name, text in texts.items():
        path = folder / name
        if not path.exists():
            write[name] = text
            continue
        try:
            present, digest = _read_field(path)
        except OSError:
            kept.append(name)
            continue
        if _is_meshgens(present, digest, previous.get(name)):
            write[name] = text
        else:
            kept.append(name)
    return write, kept


def kept_warning(case: Path, kept: list[str]) -> str:
    """The one warning line for fields kept on a re-mesh."""
    names = ", ".join(f"0/{name}" for name in kept)
    one = len(kept) == 1
    return (
        f"kept {names} of {case} (edited since meshgen wrote {'it' if one else 'them'}), not rewritten for the new mesh: "
        f"delete {'it' if one else 'them'} and mesh again to get meshgen's starting fields"
    )


def previous_fields(record_path: Path) -> dict:
    """The ``fields`` record of an existing ``meshgen.json`` ({} when there is none or it is unreadable)."""
    try:
        record = json.loads(record_path.read_bytes()[: 16 * 2**20])
    except (OSError, ValueError):
        return {}
    fields = record.get("fields") if isinstance(record, dict) else None
    return fields if isinstance(fields, dict) else {}


def _read_field(path: Path) -> tuple[str, str]:
    """(the text to parse, the SHA-256 of the file or "" for a big one) of a field file. A solved
    field of a big mesh is large (a value per cell): only its head (the banner) and its last
    ``TAIL_BYTES`` (where the boundaryField is) are read, and it is not hashed (meshgen's own
    fields are a few kB). Bytes decode as Latin-1, so a binary field parses too."""
    with open(path, "rb") as file:
        size = os.fstat(file.fileno()).st_size
        if size <= TAIL_BYTES:
            data = file.read()
            return data.decode("latin-1"), hashlib.sha256(data).hexdigest()
        head = file.read(HEAD_BYTES)
        file.seek(size - TAIL_BYTES)
        tail = file.read(TAIL_BYTES)
    found = tail.rfind(b"boundaryField")
    return (head + b"\n" + (tail[found:] if found >= 0 else b"")).decode("latin-1"), ""


def _is_meshgens(present: str, digest: str, recorded) -> bool:
    if not isinstance(recorded, dict):
        return False
    if digest and digest == recorded.get("sha256"):
        return True
    # A solver's rewrite: a banner of its own, the same boundary set-up (values aside).
    head = present[: present.find("FoamFile")] if "FoamFile" in present else present[:400]
    solved = MESHGEN_BANNER not in head
    return solved and boundary_entries(present) == recorded.get("boundary")


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()
