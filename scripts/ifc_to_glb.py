"""Convert an IFC building model (BIM: ArchiCAD, Revit, ...) to a glTF binary that ``plan`` reads.

    pip install ifcopenshell   # once, into the environment that runs this script
    python scripts/ifc_to_glb.py MODEL.ifc MODEL.glb

markerplace reads glTF, OBJ and PLY; IFC is what architects hand over. IfcOpenShell (the
field's IFC library) turns every element's geometry into triangles in world coordinates; this
script keeps each element as a glTF node (and mesh) named ``<IfcClass>_<id>_<material>``
(:func:`node_name`) with its material's colour: the class carries into the names ``plan`` reads,
so no tag goes on an ``IfcWindow``, ``IfcDoor``, ``IfcCurtainWall`` or ``IfcFurnishingElement``
(:mod:`markerplace.scene.semantics`),
writes transparent materials (window glazing) with ``alphaMode`` BLEND so that ``plan`` treats
them as glass (never a tag on them, free space bounded by them), leaves out opening volumes
(``IfcOpeningElement``) and room volumes (``IfcSpace``), and turns IFC's z-up metres into
glTF's y-up (so no ``--up`` is needed). Length units other than metres are converted by
IfcOpenShell's unit handling (``convert-back-units`` off).
"""

from __future__ import annotations

import argparse
import logging
import sys

import numpy as np

log = logging.getLogger("ifc_to_glb")

SKIP = ("IfcOpeningElement", "IfcSpace")
GLTF_FROM_IFC = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], float)  # z-up -> y-up


def _rgba(material) -> tuple[float, float, float, float]:
    diffuse = getattr(material, "diffuse", None)
    comps = getattr(diffuse, "components", diffuse)
    rgb = np.nan_to_num(np.asarray(comps if comps is not None else (0.8, 0.8, 0.8), float)[:3], nan=0.8)
    transparency = getattr(material, "transparency", 0.0) or 0.0
    transparency = 0.0 if transparency != transparency else float(transparency)
    return (*np.clip(rgb, 0, 1), float(np.clip(1.0 - transparency, 0, 1)))


def node_name(ifc_class: str, element_id: int, material: int) -> str:
    """The glTF node and mesh name of one element's faces of one material: the IFC class first
    (``IfcWindow_1234_0``), so that ``plan`` knows windows, doors and furniture by name."""
    return f"{ifc_class}_{int(element_id)}_{int(material)}"


def convert(src: str, dst: str) -> dict[str, int]:
    """Write ``dst`` (.glb) from ``src`` (.ifc); returns the element count per IFC class."""
    import ifcopenshell
    import ifcopenshell.geom
    import trimesh

    model = ifcopenshell.open(src)
    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    it = ifcopenshell.geom.iterator(settings, model, 1)
    scene = trimesh.Scene()
    counts: dict[str, int] = {}
    if not it.initialize():
        raise SystemExit(f"ifc_to_glb: error: IfcOpenShell found no geometry in {src}")
    while True:
        shape = it.get()
        cls = model.by_id(shape.id).is_a()
        g = shape.geometry
        verts = np.asarray(g.verts, float).reshape(-1, 3)
        faces = np.asarray(g.faces, np.int64).reshape(-1, 3)
        if len(faces) and cls not in SKIP:
            counts[cls] = counts.get(cls, 0) + 1
            mids = np.asarray(g.material_ids, np.int64)
            for m in np.unique(mids):
                rgba = _rgba(g.materials[m]) if m >= 0 else (0.8, 0.8, 0.8, 1.0)
                mat = trimesh.visual.material.PBRMaterial(
                    baseColorFactor=[int(round(255 * c)) for c in rgba], metallicFactor=0.0, roughnessFactor=1.0,
                    alphaMode="BLEND" if rgba[3] < 0.99 else "OPAQUE", doubleSided=True)
                part = trimesh.Trimesh(verts, faces[mids == m], process=False)
                part.remove_unreferenced_vertices()
                part.visual = trimesh.visual.TextureVisuals(material=mat)
                name = node_name(cls, shape.id, m)
                scene.add_geometry(part, node_name=name, geom_name=name, transform=GLTF_FROM_IFC)
        if not it.next():
            break
    scene.export(dst)
    return counts


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ifc", help="input .ifc")
    ap.add_argument("glb", help="output .glb")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        import ifcopenshell  # noqa: F401
    except ImportError:
        print("ifc_to_glb: error: IfcOpenShell is not installed; run `pip install ifcopenshell` first", file=sys.stderr)
        return 2
    counts = convert(args.ifc, args.glb)
    log.info("wrote %s: %s", args.glb, ", ".join(f"{n} {c}" for c, n in sorted(counts.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
