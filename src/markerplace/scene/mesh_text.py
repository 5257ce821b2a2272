"""Text of OBJ and MTL files, read one way for both (:func:`decode_text`), and the file names
they give (:func:`original_names`). Used by :mod:`.loader` and :mod:`.sanity`."""

from __future__ import annotations

import os

__all__ = ["decode_text", "original_names"]


def decode_text(data: bytes) -> str:
    """Text of an OBJ or MTL file: UTF-8 (a BOM is dropped) when the bytes are UTF-8, else
    Windows-1252 (Latin-1 for its five unassigned bytes). Never fails, and decodes an OBJ and its
    MTL files the same way, so material names (``usemtl Béton``) match (trimesh guesses each
    file's encoding separately, from its first 1000 bytes, and can guess differently)."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        pass
    try:
        return data.decode("cp1252")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def original_names(name: str) -> list[str]:
    """``name`` and, for a name read from non-UTF-8 text, the file-system names of its original bytes."""
    out = [name]
    for enc in ("cp1252", "latin-1"):
        try:
            alt = os.fsdecode(name.encode(enc))
        except UnicodeEncodeError:
            continue
        if alt not in out:
            out.append(alt)
    return out
