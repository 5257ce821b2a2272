"""OBJ/MTL text decoded one way for both files, and the file names a non-UTF-8 name stands for."""

from __future__ import annotations

import os

from markerplace.scene.mesh_text import decode_text, original_names


def test_utf8_with_or_without_bom_and_windows_1252_otherwise():
    assert decode_text("usemtl Béton\n".encode("utf-8")) == "usemtl Béton\n"
    assert decode_text(b"\xef\xbb\xbfv 0 0 0\n") == "v 0 0 0\n"  # the BOM is dropped
    assert decode_text("usemtl Béton €\n".encode("cp1252")) == "usemtl Béton €\n"
    assert decode_text(b"x \x81 \x8d") == "x \x81 \x8d"  # bytes cp1252 leaves unassigned: Latin-1


def test_original_names_lists_the_file_system_names_of_a_decoded_name():
    assert original_names("plain.png") == ["plain.png"]
    names = original_names("Béton.png")
    assert names[0] == "Béton.png" and os.fsdecode("Béton.png".encode("cp1252")) in names
    assert original_names("€.png")[1] == os.fsdecode("€.png".encode("cp1252"))  # not in Latin-1: one more only
    assert len(original_names("€.png")) == 2
