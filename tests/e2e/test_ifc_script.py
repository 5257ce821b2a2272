"""scripts/ifc_to_glb.py: IFC's material colours and transparency, and its one-line error when
IfcOpenShell is missing (the conversion itself needs IfcOpenShell, not a dependency of the
package; docs/results/real_scans.md shows it run on the FZK-Haus)."""

from __future__ import annotations

import importlib.util
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from helpers import REPO

SCRIPT = REPO / "scripts" / "ifc_to_glb.py"


@pytest.fixture(scope="module")
def ifc_to_glb():
    spec = importlib.util.spec_from_file_location("ifc_to_glb", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_glazing_keeps_its_transparency_and_ifc_z_up_becomes_gltf_y_up(ifc_to_glb):
    glass = SimpleNamespace(diffuse=SimpleNamespace(components=(0.6, 0.8, 0.9)), transparency=0.7)
    wall = SimpleNamespace(diffuse=(1.0, 1.0, 1.0), transparency=float("nan"))
    assert ifc_to_glb._rgba(glass) == pytest.approx((0.6, 0.8, 0.9, 0.3))
    assert ifc_to_glb._rgba(wall) == pytest.approx((1.0, 1.0, 1.0, 1.0))
    up_in_gltf = ifc_to_glb.GLTF_FROM_IFC @ np.array([0.0, 0.0, 1.0, 0.0])
    assert up_in_gltf[:3] == pytest.approx([0.0, 1.0, 0.0])
    assert np.linalg.det(ifc_to_glb.GLTF_FROM_IFC[:3, :3]) == pytest.approx(1.0)  # a rotation, not a mirror


def test_without_ifcopenshell_one_line_error_and_exit_2(ifc_to_glb, monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "ifcopenshell", None)  # import fails as if not installed
    assert ifc_to_glb.main([str(tmp_path / "a.ifc"), str(tmp_path / "a.glb")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install ifcopenshell" in err[0]


def test_ifc_classes_carry_into_the_names_plan_reads(ifc_to_glb, tmp_path):
    """Nodes named as convert() names them, written and read back by the loader: the IFC class
    tells windows, doors and furniture from walls (no IfcOpenShell needed for this part)."""
    import trimesh

    from markerplace.scene.loader import load_mesh_file
    from markerplace.scene.semantics import classify

    scene = trimesh.Scene()
    classes = {"IfcWallStandardCase": "structure", "IfcWindow": "windows", "IfcDoor": "doors",
               "IfcCurtainWall": "windows", "IfcFurnishingElement": "furniture", "IfcSlab": ""}
    for i, cls in enumerate(classes):
        box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
        box.apply_translation((2.0 * i, 0.0, 0.0))
        name = ifc_to_glb.node_name(cls, 100 + i, 0)
        scene.add_geometry(box, node_name=name, geom_name=name, transform=ifc_to_glb.GLTF_FROM_IFC)
    scene.export(tmp_path / "model.glb")
    parts = load_mesh_file(tmp_path / "model.glb").parts
    assert {p.name.split("_")[0]: classify(p.names).category for p in parts} == classes
