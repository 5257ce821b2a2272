"""``report.html`` of a plan run: one self-contained page for the people who act on the plan.

Sections: the scene (storeys and floor heights, floor area, camera poses, candidate spots and
what the discretization removed, from ``placement.json``'s summary), the localizability scores
before and after, how many tags (predicted recall against k, its knee, the recall target and
valid bounds: :mod:`markerplace.report.recall_section`), the top-down maps (``scores.png``, ``placement.png``, ``gain_first.png``: one
panel per storey), the model with the tags in 3D (:mod:`markerplace.report.view3d`: orbit, click a tag
for its card), a checklist, and every tag in placement order with its installer views
(:mod:`markerplace.report.installer`) and its instructions, read from each marker's ``install``
object in ``placement.json`` (:mod:`markerplace.report.instructions`: storey, wall and facing,
height above the floor under it, distances along the wall to the nearest corner or door edge on
each side, tag id, printed size, pages of tags.pdf).

Positions shown are in the user's frame (the model file's coordinates, z up, metres); the
directions follow the convention of :mod:`markerplace.report.captions` (+x east, +y north),
which the page states.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

from markerplace.markers import load_markers
from markerplace.plan.discretize.candidate_rules import RULES, rule_words
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.report.html import esc, img, jpeg_uri, png_file_uri, table, write_page
from markerplace.report.installer import render_installer_views
from markerplace.report.instructions import along_words, height_words, install_to_frame, pages_words, place_from_install, storey_words, wall_words
from markerplace.report.recall_section import recall_section
from markerplace.report.review import REVIEW_SCRIPT, reject_button, review_box, surface_line
from markerplace.report.view3d import scene_view_html
from markerplace.scene.raycast import RayCaster
from markerplace.scene.worldframe import markers_to_internal

log = logging.getLogger(__name__)

__all__ = ["write_plan_report"]

CONVENTION = ("Directions name the model's axes like a map seen from above: <b>+x = east, +y = north</b> "
              "(-x west, -y south; the model's +y, not magnetic north; up on the maps above). A tag "
              "<i>faces</i> the way its printed side looks (its wall normal, towards the room) and hangs "
              "<i>on</i> the wall on the opposite side: a tag that faces west is on the east wall. "
              "Left and right are as seen standing in front of the wall, facing it. Heights are of the "
              "tag centre (the middle of the black square) above the floor at the foot of the wall under it "
              "(where you stand, never a table or a shelf). Distances run along the wall plane from the "
              "nearest reference on each side to the tag centre: a <i>corner</i> (the next wall), a <i>door "
              "edge</i> (the edge of a doorway) or the <i>end of the wall</i> (an outside corner, the end of the "
              "surface); furniture in front of the wall, a picture or a window do not end it, so a tape on the "
              "wall at the tag's height and one along the floor line read the same. Measured with rays on the "
              "model; coordinates are the model's, in metres, z up. placement.csv and placement.json "
              "(<code>install</code>) hold the same instructions.")


def _scene_section(doc: dict, num_markers: int) -> str:
    s = doc.get("summary", {})
    disc = s.get("discretization", {})
    per = disc.get("per_storey", [])
    rows = [[f"storey {p['storey']}", p["floor_z"], p["open_floor_m2"], p["free_m2"], p["locations"],
             p["candidates"], len(p.get("unreached", []))] for p in per]
    total = [["all planned", "", sum(p["open_floor_m2"] for p in per), sum(p["free_m2"] for p in per),
              sum(p["locations"] for p in per), sum(p["candidates"] for p in per),
              sum(len(p.get("unreached", [])) for p in per)]] if len(per) > 1 else []
    removed = disc.get("candidates_removed", {})
    yaws = s.get("num_poses", 0) // max(s.get("num_locations", 1), 1)
    facts = [
        ["scene", doc.get("scene", "?")],
        ["method", doc.get("method", "?")],
        ["markers placed", num_markers],
        ["storeys found (floor heights, m)", ", ".join(f"{z:.2f}" for z in s.get("storeys", [])) or "?"],
        ["storeys planned", ", ".join(str(v) for v in s.get("planned_storeys", []))],
        ["camera poses", f"{s.get('num_poses', 0)} ({s.get('num_locations', 0)} locations x {yaws} yaws)"],
        ["wall spots found", disc.get("wall_spots", "?")],
        ["removed (a spot counts once, under the first rule)",
         _removed_words(removed, float((doc.get("markers") or [{}])[0].get("size", 0.4)))],
        ["candidate spots competing", s.get("num_candidates", "?")],
    ]
    frames = disc.get("frames")
    if frames:  # plan --frames: the poses are a real sequence's (plan/frames)
        surface = "the surface fused from those frames" if frames.get("surface") == "fused" else f"the mesh {frames.get('surface')}"
        facts[5] = ["camera poses", f"{s.get('num_poses', 0)} (the frames' own 6-DoF poses)"]
        facts.insert(1, ["planned from frames", f"{frames.get('count')} of {frames.get('total')} frames (every "
                         f"{frames.get('step')}) of {frames.get('root')}, {frames.get('layout')} layout; tags on "
                         f"{surface}; camera path on camera_path.png"])
    unreached = [f"storey {p['storey']}: {u['area_m2']:.1f} m^2 around ({u['centre'][0]:.1f}, {u['centre'][1]:.1f})"
                 for p in per for u in p.get("unreached", [])]
    note = ("<p class=\"note\">Floor regions without cameras (reached only through a gap narrower than a person, "
            f"or not connected): {esc('; '.join(unreached))}</p>") if unreached else ""
    return ("<h2>Scene</h2>" + table(None, facts) +
            table(["storey", "floor (m)", "open floor (m^2)", "free (m^2)", "camera locations", "candidate spots",
                   "regions without cameras"], rows + total) + note)


def _removed_words(removed: dict, size: float) -> str:
    """What the candidate rules and the planner removed, e.g. ``"3 on glass, 2 on doors, ...,
    1 seen by no camera"`` (:mod:`markerplace.plan.discretize.wall_candidates`; ``size``: the tag, metres)."""
    words = [f"{removed[r]} {rule_words(r, size)}" for r in RULES if removed.get(r)]
    words += [f"{removed['not seen']} seen by no camera"] if removed.get("not seen") else []
    return ", ".join(words) or "none"


def _scores_section(s: dict) -> str:
    rows = [["mean", s["mean_score_before"], s["mean_score_after"], s["mean_score_after"] - s["mean_score_before"]],
            ["10th percentile", s["p10_score_before"], s["p10_score_after"],
             s["p10_score_after"] - s["p10_score_before"]]]
    if "where" in s:  # plan --where: the objective's weighted mean
        w = s["where"]
        rows.append(["weighted mean (--where)", w["mean_score_before"], w["mean_score_after"],
                     w["mean_score_after"] - w["mean_score_before"]])
    return ("<h2>Scores before and after</h2><p class=\"note\">Localizability score of a camera pose: the negative "
            "entropy of its pose posterior (nats; higher is better), over every feasible pose. The 10th "
            "percentile is what the worst-served places get.</p>"
            + table(["score over camera poses", "no markers", "with the plan", "change"], rows))


def _maps_section(out_dir: Path) -> str:
    figs = [("camera_path.png", "Planned from frames: the frames' camera path (blue, arrows = headings), candidate "
             "spots (orange) and the tags (red, numbered); grey = surface, white = where the cameras went."),
            ("placement.png", "The plan: numbered tags (arrows point where each tag faces) over the scores "
             "after placement; one panel per storey."),
            ("scores.png", "Scores without markers (dark = low); blue ticks are candidate spots."),
            ("gain_first.png", "Information gain of the first tag (dark = high)."),
            ("where.png", "Where the cameras will be (--where): the weight of each camera location in the "
                          "objective and the predicted recall (dark = high, mean over yaws).")]
    parts = [img(png_file_uri(out_dir / name), name, text) for name, text in figs if (out_dir / name).is_file()]
    return "<h2>Maps</h2>" + "".join(parts)


def _order_note(method) -> str:
    """What the placement order means for ``method``: greedy methods pick the most useful tag
    first, the others have no ranking."""
    cls = PLACEMENT_METHODS.get(method)
    return "; each earlier tag helps most" if cls is not None and cls.nested else " (the order is not a ranking)"


def write_plan_report(out_dir: str | Path, scene, disc, height: float, world_offset=None) -> Path:
    """Write ``report.html`` into a plan's run folder and return its path.

    Args:
        out_dir: the run folder holding ``placement.json`` and the figures.
        scene: the scene in its internal frame (rendered and ray cast).
        disc: the run's :class:`~markerplace.plan.discretize.artifact.Discretization` (internal
            frame): storeys and occupancy (where the installer camera may stand).
        height: eye level above the local floor (``--height``), metres (unused: each marker's
            ``install`` object carries its floor and height; kept for callers).
        world_offset: (3,) user-frame offset of the internal frame (``p_internal = p_user -
            offset``, :mod:`markerplace.scene.worldframe`); None = not shifted.
    """
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    doc = json.loads((out_dir / "placement.json").read_text())
    records = doc.get("markers", [])
    offset = np.zeros(3) if world_offset is None else np.asarray(world_offset, float)
    markers = markers_to_internal(load_markers(out_dir / "placement.json"), offset)
    caster = RayCaster(*scene.geometry())
    planned = [int(v) for v in disc.planned_storeys]
    installs = [r["install"] for r in records]
    places = [place_from_install(install_to_frame(i, -offset)) for i in installs]

    def occupancy_of(i: int):
        s = installs[i]["storey"]
        return disc.occupancy[planned.index(s)] if s in planned else None

    labels = [f"#{r['order']} id {r['tag_id']}" for r in records]
    views = render_installer_views(scene, markers, places, caster, occupancy_of, disc.grid_origin,
                                   disc.grid_resolution, labels) if markers else []

    checklist, cards = [], []
    for r, inst, v in zip(records, installs, views):
        x, y, z = r["position"]
        checklist.append([r["order"], r["tag_id"], storey_words(inst), wall_words(inst), round(inst["height_m"], 2),
                          along_words(inst), pages_words(inst.get("pages", []))])
        sheet = f"tags/{r['order']:02d}_tag{r['tag_id']}.svg"
        pages = inst.get("pages", [])
        items = [
            f"<b>{esc(storey_words(inst).capitalize())}</b>; on the <b>{esc(wall_words(inst))}</b>.",
            f"<b>{esc(height_words(inst).capitalize())}</b> (the middle of the black square; the floor at the foot "
            "of the wall, where you stand, never furniture).",
            f"Centre <b>{esc(along_words(inst))}</b> (as you face the wall, along the wall).",
            f"Tag {esc(r['family'])} id <b>{r['tag_id']}</b>, black square <b>{1000 * r['size']:.0f} mm</b>; "
            f"print sheet <code>{esc(sheet)}</code>"
            + (f" or page(s) {pages_words(pages)} of <code>tags.pdf</code>" if pages else "")
            + "; hang it with the caption (\"this edge down\") at the bottom.",
            f"Model coordinates of the centre: ({x:.2f}, {y:.2f}, {z:.2f}) m.",
        ]
        on = surface_line(r)  # what the tag is on (report/review.py)
        items = items[:1] + ([on] if on else []) + items[1:]
        cards.append(
            f'<div class="tag" id="tag{r["order"]}"><h3>#{r["order"]}: tag id {r["tag_id"]}</h3>'
            f'<ul class="caption">{"".join(f"<li>{t}</li>" for t in items)}</ul>{reject_button(r)}<div class="views">'
            + img(jpeg_uri(v.close), f"tag {r['order']} close view",
                  f"Standing {v.close_distance:.1f} m in front of the spot at eye level; the tag is outlined.")
            + img(jpeg_uri(v.wide), f"tag {r['order']} wide view",
                  f"The same wall from {v.wide_distance:.1f} m: orange lines measure the distance along the wall "
                  "and the height above the floor.")
            + "</div></div>")

    title = f"Marker plan: {doc.get('scene', '?')}"
    body = [f"<h1>{esc(title)}</h1>",
            f"<p>{len(records)} AprilTags ({esc(doc.get('method', '?'))}) in placement order: hang #1 first"
            f"{_order_note(doc.get('method'))}. Generated by markerplace from <code>placement.json</code>.</p>",
            _scene_section(doc, len(records)), _scores_section(doc["summary"]), recall_section(doc),
            _maps_section(out_dir),
            "<h2>In 3D</h2>", scene_view_html(scene, markers, planned_labels=[str(r["order"]) for r in records],
                                              planned_cards=[f"tag{r['order']}" for r in records]),
            "<h2>Tags</h2>", f"<p class=\"note\">{CONVENTION}</p>",
            table(["#", "tag id", "storey", "wall", "centre above the floor (m)", "along the wall, to the centre",
                   "tags.pdf pages"], checklist),
            review_box(str(doc.get("scene", "?")), str(out_dir)), *cards, REVIEW_SCRIPT]
    path = write_page(out_dir / "report.html", title, "\n".join(body))
    log.info("report.html: %d tags, %.1f s", len(records), time.perf_counter() - t0)
    return path
