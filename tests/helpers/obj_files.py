"""OBJ + MTL test inputs the project did not draw with its own exporter."""

from __future__ import annotations

from pathlib import Path


def latin1_room(folder: Path) -> Path:
    """A 4 x 4 m room whose material names are Latin-1 (an OBJ comment that makes trimesh guess
    ISO-8859-14 for the OBJ and Windows-1250 for the MTL, so ``Béton 3°`` differs between them)."""
    names = ["Béton 3°", "Plâtre", "Bois", "Brique"]
    colours = ["0.6 0.6 0.6", "0.9 0.9 0.9", "0.5 0.4 0.3", "0.7 0.2 0.1"]
    quads = [[(0, 0, 0), (4, 0, 0), (4, 4, 0), (0, 4, 0)], [(0, 0, 0), (0, 0, 3), (4, 0, 3), (4, 0, 0)],
             [(4, 0, 0), (4, 0, 3), (4, 4, 3), (4, 4, 0)], [(4, 4, 0), (4, 4, 3), (0, 4, 3), (0, 4, 0)]]
    obj, n = ["# modèle exporté, 3° étage", "mtllib mat.mtl"], 0
    for i, q in enumerate(quads):
        obj += [f"o part{i}", f"usemtl {names[i]}"] + ["v %g %g %g" % p for p in q]
        obj += [f"f {n + 1} {n + 2} {n + 3}", f"f {n + 1} {n + 3} {n + 4}"]
        n += 4
    mtl = [line for nm, c in zip(names, colours) for line in (f"newmtl {nm}", f"Kd {c}", "")]
    (folder / "room.obj").write_bytes("\n".join(obj).encode("latin-1"))
    (folder / "mat.mtl").write_bytes("\n".join(mtl).encode("latin-1"))
    return folder / "room.obj"
