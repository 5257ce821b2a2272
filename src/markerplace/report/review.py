"""The review loop of ``report.html``: what each tag is on, and a button per tag that rejects its
spot into a downloadable exclusion file for ``plan --exclude``.

The page stays self-contained: one small inline script (no library, no network) keeps the
rejected spots and rewrites the download link's ``href`` as a ``data:`` URL holding the JSON of
:mod:`markerplace.plan.discretize.exclusion` (``format``, ``scene``, ``spots``: x, y, z in the model's
frame as placement.json has them, ``radius`` half the tag size, ``order``, ``tag_id``,
``note``). ``plan SCENE --out SAME_FOLDER --exclude rejected.json`` then replans from the cached
stages and prints what changed.
"""

from __future__ import annotations

import json
from urllib.parse import quote

from markerplace.report.html import esc

__all__ = ["surface_line", "reject_button", "review_box", "REVIEW_SCRIPT"]

REVIEW_SCRIPT = """<script>
(function () {
  var rejected = {};
  var link = document.getElementById("mp-rejected-download");
  var count = document.getElementById("mp-rejected-count");
  function update() {
    var spots = Object.keys(rejected).sort(function (a, b) { return a - b; })
      .map(function (k) { return rejected[k]; });
    var doc = {format: "markerplace-exclude/1", scene: link.dataset.scene, spots: spots};
    link.href = "data:application/json;charset=utf-8," + encodeURIComponent(JSON.stringify(doc, null, 2) + "\\n");
    link.setAttribute("aria-disabled", spots.length ? "false" : "true");
    count.textContent = String(spots.length);
  }
  Array.prototype.forEach.call(document.querySelectorAll("button.mp-reject"), function (b) {
    b.addEventListener("click", function () {
      var k = b.dataset.order;
      if (rejected[k]) {
        delete rejected[k];
        b.classList.remove("on");
        b.textContent = "Reject this spot";
      } else {
        rejected[k] = {x: Number(b.dataset.x), y: Number(b.dataset.y), z: Number(b.dataset.z),
                       radius: Number(b.dataset.radius), order: Number(k), tag_id: Number(b.dataset.tag),
                       note: b.dataset.note};
        b.classList.add("on");
        b.textContent = "Rejected (click to undo)";
      }
      update();
    });
  });
  update();
})();
</script>"""


def surface_line(record: dict) -> str | None:
    """The card line saying what a tag is on (None for a placement.json without ``surface``)."""
    surface = record.get("surface")
    if not surface:
        return None
    part = record.get("surface_part")
    return f"On the <b>{esc(surface)}</b>" + (f" (model part <code>{esc(part)}</code>)." if part else ".")


def reject_button(record: dict) -> str:
    """The per-tag button: rejects the spot (radius half the tag size) into the download."""
    x, y, z = (float(v) for v in record["position"])
    radius = round(0.5 * float(record.get("size", 0.4)), 4)
    note = f"tag #{record['order']} (id {record['tag_id']}) on the {record.get('surface') or 'wall'}"
    return (f'<p><button type="button" class="mp-reject" data-order="{int(record["order"])}" '
            f'data-tag="{int(record["tag_id"])}" data-x="{x:.4f}" data-y="{y:.4f}" data-z="{z:.4f}" '
            f'data-radius="{radius:g}" data-note="{esc(note)}">Reject this spot</button> '
            "<span class=\"note\">(a door that opens over it, a wall to be painted, ...: adds it to "
            "<code>rejected.json</code>, see <i>Review</i> above the tags)</span></p>")


def review_box(scene: str, out_dir: str = "PLAN_DIR") -> str:
    """The box with the download link and how to replan (the page ends with :data:`REVIEW_SCRIPT`)."""
    empty = json.dumps({"format": "markerplace-exclude/1", "scene": scene, "spots": []})

    return ("<div class=\"review\"><p><b>Review.</b> Reject the spots a person would not use with the "
            "<i>Reject this spot</i> button of each tag, then download the file and replan; the cached stages "
            "are reused, so it takes seconds, and the run prints which tags changed:</p>"
            f'<p><a id="mp-rejected-download" class="mp-download" download="rejected.json" '
            f'data-scene="{esc(scene)}" href="data:application/json;charset=utf-8,{esc(quote(empty))}" '
            'aria-disabled="true">Download rejected.json</a> (spots rejected: <span id="mp-rejected-count">0</span>)</p>'
            f"<p><code>markerplace plan {esc(scene)} --out {esc(out_dir)} --exclude rejected.json</code> "
            "(with the options of the first run)</p></div>")
