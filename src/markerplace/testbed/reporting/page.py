"""``report.html`` of an evaluation: one self-contained page of what the markers bought.

Sections: the settings, the recall tables (``tables.md`` as HTML tables), recall vs k
(``recall_vs_k.png``), and a gallery of the test images that the plan fixes and breaks
relative to no markers: for the plan's largest k and the first test set, at the main threshold,
up to :data:`GALLERY_MAX` of each, every one with the test image as the camera saw it (the
plan's tags drawn), the view from the pose the plan's localization estimated and from the one
localizing without markers estimated, their errors in cm and degrees, and the true and
estimated poses on the storey's top-down map. The plan is ``omp`` when it was evaluated, else
the first ``--placements`` method.

Computed from the stored predictions in the report stage (:func:`markerplace.testbed.reporting.summary.
write_outputs` calls :func:`write_evaluation_report`); nothing is localized again, only the
gallery's images are rendered.

Frames: poses are the scene's internal frame (world z up, metres, OpenCV camera); positions
shown are in the user's frame (shifted by the scene's world offset).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from markerplace.plan.discretize.artifact import load as load_disc
from markerplace.render.renderer import Renderer
from markerplace.report.html import esc, img, jpeg_uri, markdown_to_html, png_file_uri, png_uri, table, write_page
from markerplace.scene.worldframe import world_offset
from markerplace.simulation import metrics
from markerplace.simulation.conditions import CLEAN
from markerplace.simulation.marker_sets import NO_MARKERS, RESERVED_NAMES, baseline_methods
from markerplace.simulation.metrics import hit_mask, pose_errors_batch

log = logging.getLogger(__name__)

__all__ = ["GALLERY_MAX", "gallery_selection", "write_evaluation_report"]

GALLERY_MAX = 6
"""At most this many fixed and this many broken test images are shown."""
MAP_WIDTH = 360
"""Width of a gallery item's top-down map, pixels."""
TRUE_BGR, PLAN_BGR, NONE_BGR = (40, 160, 40), (200, 0, 200), (200, 120, 0)


def _plan_method(placements) -> str | None:
    methods = [p.method for p in placements if p.k > 0]
    if "omp" in methods:
        return "omp"
    others = [m for m in methods if m not in (NO_MARKERS, *RESERVED_NAMES) and m not in baseline_methods()]
    return others[0] if others else None


def gallery_selection(t_plan: np.ndarray, r_plan: np.ndarray, t_none: np.ndarray, r_none: np.ndarray,
                      threshold: tuple[float, float], limit: int = GALLERY_MAX) -> tuple[np.ndarray, np.ndarray]:
    """Which test images the plan fixes and breaks, most telling first.

    Args:
        t_plan, r_plan: (N,) translation (metres) and rotation (degrees) errors with the plan's
            markers (inf where localization failed); t_none, r_none: the same without markers.
        threshold: (metres, degrees) of a hit (inclusive).
        limit: at most this many of each.

    Returns:
        (fixed, broken) index arrays: fixed = a miss without markers and a hit with them, sorted
        by the error without markers, largest (and failures) first; broken = the reverse, sorted
        by the error with the plan. Ties keep the test-image order.
    """
    hit_plan = hit_mask(t_plan, r_plan, *threshold)
    hit_none = hit_mask(t_none, r_none, *threshold)

    def order(idx: np.ndarray, t_err: np.ndarray) -> np.ndarray:
        key = np.nan_to_num(np.asarray(t_err, float)[idx], nan=np.inf)
        return idx[np.argsort(-key, kind="stable")][:limit]

    return order(np.flatnonzero(hit_plan & ~hit_none), t_none), order(np.flatnonzero(~hit_plan & hit_none), t_plan)


def _map_image(disc, layer: int, poses: list[tuple[np.ndarray, tuple]]) -> np.ndarray:
    """(H, W, 3) RGB top-down map of one occupancy layer (cropped to the storey, x right, y up)
    with an arrow per (4, 4) ``world_from_cam`` (non-finite: skipped) in its BGR colour; the
    first pose (the truth) gets a ring, the others a dot."""
    import cv2

    occ = disc.occupancy[layer]
    rows, cols = np.nonzero(occ >= 0)
    if len(rows) == 0:
        rows, cols = np.array([0, occ.shape[0] - 1]), np.array([0, occ.shape[1] - 1])
    pad = int(round(0.5 / disc.grid_resolution))
    r0, r1 = max(rows.min() - pad, 0), min(rows.max() + pad + 1, occ.shape[0])
    c0, c1 = max(cols.min() - pad, 0), min(cols.max() + pad + 1, occ.shape[1])
    crop = occ[r0:r1, c0:c1]
    base = np.full(crop.shape + (3,), 235, np.uint8)
    base[crop == 0] = 255
    base[crop == 1] = 64
    f = MAP_WIDTH / crop.shape[1]
    im = cv2.resize(base[::-1], (MAP_WIDTH, max(1, int(round(crop.shape[0] * f)))), interpolation=cv2.INTER_NEAREST)
    im = np.ascontiguousarray(im[..., ::-1])
    x0 = disc.grid_origin[0] + c0 * disc.grid_resolution
    y0 = disc.grid_origin[1] + r0 * disc.grid_resolution
    scale = f / disc.grid_resolution  # pixels per metre

    def pix(x: float, y: float) -> tuple[int, int]:
        return int(round((x - x0) * scale)), int(round(im.shape[0] - (y - y0) * scale))

    for k, (T, color) in enumerate(poses):
        if T is None or not np.isfinite(T).all():
            continue
        p = T[:3, 3]
        fwd = T[:3, 2]
        a = pix(p[0], p[1])
        b = pix(p[0] + 0.7 * fwd[0], p[1] + 0.7 * fwd[1])
        if k == 0:  # the truth: a ring, so estimates on top of it stay visible
            cv2.circle(im, a, 10, color, 2, cv2.LINE_AA)
        else:
            cv2.circle(im, a, 4, color, -1, cv2.LINE_AA)
        cv2.arrowedLine(im, a, b, color, 2, cv2.LINE_AA, tipLength=0.3)
    return im[..., ::-1].copy()


def _error_text(t: float, r: float, threshold: tuple[float, float]) -> str:
    if not (np.isfinite(t) and np.isfinite(r)):
        return '<span class="bad">localization failed</span>'
    hit = t <= threshold[0] and r <= threshold[1]
    return f'<span class="{"good" if hit else "bad"}">{100 * t:.1f} cm, {r:.1f} deg</span>'


def _view(rgb: np.ndarray | None, alt: str, caption: str) -> str:
    if rgb is None:
        return f'<figure><div class="failed">localization failed: no estimate</div><figcaption>{esc(caption)}</figcaption></figure>'
    return img(jpeg_uri(rgb), alt, caption)


def _gallery(out: Path, scene, placements, predictions, test_poses, config, camera, threshold, label) -> str:
    method = _plan_method(placements)
    ts = config.test.sets[0]
    if method is None or not any(p.method == NO_MARKERS for p in placements):
        return ("<p class=\"note\">No gallery: it compares a plan (omp or a --placements method) with no markers; "
                "evaluate both (<code>--methods none,omp</code>).</p>")
    plan = max((p for p in placements if p.method == method and p.run == 0 and (p.method, p.run, p.k, ts) in predictions),
               key=lambda p: p.k, default=None)
    none = next((p for p in placements if p.method == NO_MARKERS and (p.method, p.run, p.k, ts) in predictions), None)
    if plan is None or none is None:
        return f"<p class=\"note\">No gallery: no predictions of {esc(method)} and of no markers on <code>{esc(ts)}</code>.</p>"
    truth = test_poses[ts].world_from_cam
    est_plan = predictions[(plan.method, plan.run, plan.k, ts)]
    est_none = predictions[(none.method, none.run, none.k, ts)]
    t_plan, r_plan = pose_errors_batch(est_plan, truth)
    t_none, r_none = pose_errors_batch(est_none, truth)
    fixed, broken = gallery_selection(t_plan, r_plan, t_none, r_none, threshold)
    hit_plan, hit_none = hit_mask(t_plan, r_plan, *threshold), hit_mask(t_none, r_none, *threshold)
    head = (f"<p>{esc(method)} with k = {plan.k} tags, test set <code>{esc(ts)}</code>, at {esc(label)}: "
            f"fixes <b>{int(np.sum(hit_plan & ~hit_none))}</b> and breaks <b>{int(np.sum(~hit_plan & hit_none))}</b> "
            f"of {len(truth)} test images relative to no markers (up to {GALLERY_MAX} of each shown, "
            "most telling first). Map: <span style=\"color:#28a028\">green ring = true pose</span>, "
            "<span style=\"color:#c800c8\">magenta = estimate with the plan</span>, "
            "<span style=\"color:#0078c8\">blue = estimate without markers</span>.</p>")
    if scene is None:
        return head + "<p class=\"note\">No images: the scene was not given to the report stage.</p>"
    disc_path = out / "plan" / "discretization.npz"
    disc = load_disc(disc_path) if disc_path.is_file() else None
    offset = world_offset(scene)
    chosen = [("fixed", int(i)) for i in fixed] + [("broken", int(i)) for i in broken]
    renders: dict = {}
    with Renderer(scene, camera, markers=list(plan.markers)) as r:
        for _, i in chosen:
            renders[("query", i)] = r.render(truth[i], depth=False, normal=False).rgb
            if np.isfinite(est_plan[i]).all():
                renders[("plan", i)] = r.render(est_plan[i], depth=False, normal=False).rgb
        r.set_markers(list(none.markers))
        for _, i in chosen:
            if np.isfinite(est_none[i]).all():
                renders[("none", i)] = r.render(est_none[i], depth=False, normal=False).rgb
    sections = []
    for kind, title in (("fixed", "Fixed by the plan (missed without markers)"),
                        ("broken", "Broken by the plan (localized without markers, missed with them)")):
        items = []
        for _, i in [c for c in chosen if c[0] == kind]:
            x, y, z = truth[i][:3, 3] + offset
            yaw = np.degrees(np.arctan2(truth[i][1, 2], truth[i][0, 2]))
            parts = [_view(renders[("query", i)], f"test image {i}", f"test image {i}: the camera's view with the plan's tags"),
                     _view(renders.get(("plan", i)), f"estimate {i} with the plan", "from the pose estimated with the plan"),
                     _view(renders.get(("none", i)), f"estimate {i} without markers", "from the pose estimated without markers")]
            if disc is not None:
                layer = int(np.flatnonzero(disc.planned_storeys == disc.pose_storey[test_poses[ts].source_index[i]])[0])
                parts.append(img(png_uri(_map_image(disc, layer, [(truth[i], TRUE_BGR), (est_none[i], NONE_BGR),
                                                                   (est_plan[i], PLAN_BGR)])),
                                 f"map {i}", "true and estimated poses"))
            items.append(f'<div class="tag"><h4>test image {i}: true pose ({x:.2f}, {y:.2f}, {z:.2f}) m, yaw {yaw:.0f} deg</h4>'
                         f"<p>error with the plan: {_error_text(t_plan[i], r_plan[i], threshold)}; "
                         f"without markers: {_error_text(t_none[i], r_none[i], threshold)}</p>"
                         f'<div class="gallery">{"".join(parts)}</div></div>')
        sections.append(f"<h3>{esc(title)}</h3>" + ("".join(items) or "<p class=\"note\">none</p>"))
    return head + "".join(sections)


def write_evaluation_report(out: str | Path, scene_name: str, placements, predictions: dict, test_poses: dict,
                            config, camera, scene=None) -> Path:
    """Write ``report.html`` into an evaluation's run folder (after ``tables.md`` and
    ``recall_vs_k.png``) and return its path.

    Args:
        out: the run folder.
        scene_name: label of the page.
        placements: the evaluated :class:`~markerplace.simulation.marker_sets.PlacementRun` list.
        predictions: ``(method, run, k, test set) -> (N, 4, 4)`` estimated ``world_from_cam``
            (all NaN where localization failed).
        test_poses: test set -> :class:`~markerplace.simulation.pose_sampling.TestPoses` (truth).
        config: the :class:`~markerplace.testbed.config.EvaluateConfig`.
        camera: :class:`~markerplace.geometry.Intrinsics` of the test images.
        scene: the scene (internal frame) to render the gallery; None = gallery without images.
    """
    t0 = time.perf_counter()
    out = Path(out)
    threshold = metrics.MAIN_THRESHOLD if metrics.MAIN_THRESHOLD in config.thresholds else config.thresholds[0]
    label = metrics.threshold_label(threshold)
    settings = [["test images per set", config.test.tests], ["test sets", ", ".join(config.test.sets)],
                ["methods", ", ".join(sorted({p.method for p in placements}))],
                ["k", ", ".join(str(k) for k in sorted(set(config.study.ks)))],
                ["runs per randomized method", config.study.runs], ["localizer", config.localization.localizer],
                ["thresholds", ", ".join(metrics.threshold_label(t) for t in config.thresholds)]]
    if tuple(config.test.conditions) != (CLEAN,):
        settings.append(["query conditions (the gallery: clean)", ", ".join(config.test.conditions)])
    tables_md = out / "tables.md"
    body = [f"<h1>Evaluation: {esc(scene_name)}</h1>",
            "<p>Simulated localization of test images with each marker placement (the paper's testbed). "
            "Recall = share of test images localized within the threshold; a failed localization is a miss.</p>",
            "<h2>Settings</h2>", table(None, settings),
            "<h2>Recall</h2>", markdown_to_html(tables_md.read_text(), heading_offset=2) if tables_md.is_file() else ""]
    if (out / "recall_vs_k.png").is_file():
        body += ["<h2>Recall vs number of tags</h2>", img(png_file_uri(out / "recall_vs_k.png"), "recall vs k")]
    body += ["<h2>Test images the plan fixes and breaks</h2>",
             _gallery(out, scene, placements, predictions, test_poses, config, camera, threshold, label)]
    path = write_page(out / "report.html", f"Evaluation: {scene_name}", "\n".join(body))
    log.info("report.html: %.1f s", time.perf_counter() - t0)
    return path
