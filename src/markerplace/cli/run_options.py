"""The options of ``plan``, ``evaluate`` and ``study`` that set no config field, with their docs
text: where the inputs are, where the outputs go and how a run behaves. Every other option is a
config field's (:func:`markerplace.settings.setting`). ``docs/cli.md``'s option tables read them
here (:mod:`markerplace.cli.option_docs`); ``tests/test_settings.py`` checks that every flag of a
command is one or the other."""

from __future__ import annotations

__all__ = ["RUN_OPTIONS"]

_SCENE_RUN_OPTIONS = {
    "scene": ("required", "a built-in scene name (`markerplace scene list`) or a mesh file (.glb, .gltf, .obj, .ply)"),
    "--up": ("z (glTF: y)", "up axis of a mesh file (`z`, `y`, `-y`, `x`, `-x`, `-z`; `--up -x` and `--up=-x` both "
                            "work, as do `--start -2.5,1` and `--pose -1,2,1.5,90`): OBJ/PLY have no convention; glTF "
                            "is y-up by its specification, which `--up` overrides"),
    "--unit-scale": ("1", "multiply mesh coordinates by this to get metres (e.g. 0.01 for cm, 0.001 for mm)"),
    "--seed": ("0", "seed of the procedural generator of built-in scenes"),
}
_COMMON_RUN_OPTIONS = {
    "--force": ("off", "run even when the size guard refuses (see below)"),
    "--adopt": ("off", "use a non-empty `--out` folder markerplace did not make: the run's files are added, the files "
                       "already there are never replaced or deleted (see [Run folders](#run-folders-what-markerplace-"
                       "writes-and-deletes))"),
    "--quiet": ("off", None),
    "--method-conf": ("none", "`[METHOD.]KEY=VALUE`: a setting of a placement method's own `Config` (the table "
                              "`[placement.methods.METHOD]` of a `--config` file, see [Settings files]"
                              "(#settings-files-plan---config)), e.g. `v=80` or `expected-recall.calibration_runs=5`; "
                              "METHOD (with `-`) defaults to `--method` in `plan` and must be given in `evaluate` and "
                              "`study`; repeat it for more; a key the method does not have is refused with its "
                              "keys"),
}

RUN_OPTIONS: dict[str, dict[str, tuple[str | None, str | None] | None]] = {
    "plan": {**_SCENE_RUN_OPTIONS,
             "scene": ("required unless `--frames`", "a built-in scene name (`markerplace scene list`) or a mesh "
                                                    "file (.glb, .gltf, .obj, .ply); left out with `--frames`"),
             "--frames": ("none", "plan at the camera poses of this RGB-D sequence, from its own images (markerplace, "
                                  "TUM, 7-Scenes, nerfstudio or Stray Scanner layout, [docs/rgbd_layout.md]"
                                  "(rgbd_layout.md); `--up` gives the up axis of its world), tags on the surface fused "
                                  "from the frames; give no scene (see [Planning from RGB-D frames]"
                                  "(#planning-from-rgb-d-frames-plan---frames))"),
             "--format": None, "--intrinsics": None,
             "--mesh": ("none", "with `--frames`: put tags on this mesh (the frames' world frame, z up, metres) "
                                "instead of the surface fused from the frames"),
             "--frame-step": ("at most 400 poses", "with `--frames`: every N-th frame is a camera pose"),
             "--out": None, "--where": None,
             "--config": ("none", "settings from a TOML file or a plan's `config.json` (see "
                                  "[Settings files](#settings-files-plan---config)); options given on the command "
                                  "line override it"),
             "--existing": ("none", "markers already on the walls (same format as placement.json); each must hang "
                                    "on a wall"),
             "--exclude": ("none", "spots and boxes where no tag may go, in the model's coordinates (format below; "
                                   "`report.html`'s review buttons download one); applied when placing, so a re-run "
                                   "reuses every cached stage and renders nothing"),
             "--paper": ("a4", "paper of `tags.pdf`: `a4`, `letter`, `a3` (a tag larger than the page is tiled) or "
                               "`none` (one page per tag at its own size)"),
             "--with-map": ("off", "also extract the evaluation's marker-free map (OpenCV-default SIFT and tags) "
                                   "from observe's renders, so that a later `evaluate --plan` renders no map image "
                                   "(observe takes longer, see docs/results/benchmarks.md); always on with "
                                   "expected-recall, --target-recall or --recall-curve, whose calibration needs "
                                   "the map"),
             **_COMMON_RUN_OPTIONS},
    "evaluate": {**_SCENE_RUN_OPTIONS,
                 "scene": ("required unless `--plan`", "a built-in scene name or a mesh file; left out with `--plan` "
                                                       "(which brings its own)"),
                 "--seed": ("0", "seeds the scene generator of built-ins, the localizer's RANSAC, the VLAD codebook, "
                                 "the held-out ceiling's splits and (unless `--test-seed`) the test poses; with "
                                 "`--plan` the plan's"),
                 "--out": None, "--where": None,
                 "--placements": ("none", "also evaluate every `placement.json` under DIR (e.g. from `plan`) as a "
                                          "method (checked before any work)"),
                 "--plan": ("none", "start from a finished `plan` folder (PLAN_DIR): its scene, settings and placement "
                                    "(evaluated as its method's, `--k` up to its k, default its k); its cached stages "
                                    "(discretization, observations, look-alikes, calibration) are reused, the folder "
                                    "is only read; an option that differs from the plan's is refused"),
                 "--frames": ("none", "evaluate on a real RGB-D sequence (any layout of [docs/rgbd_layout.md]"
                                      "(rgbd_layout.md)) instead of a scene: plan at the map frames' poses, "
                                      "composite each placement's tags into the real photographs, localize the "
                                      "query frames (see [Real photographs](#real-photographs-evaluate---frames))"),
                 "--format": ("auto", "with `--frames`: the layout of the frame folder"),
                 "--intrinsics": ("none", "with `--frames`: the camera of a TUM sequence"),
                 "--mesh": ("none", "with `--frames`: a mesh (the frames' world, z up, metres) for the tag spots and "
                                    "the renders instead of the surface fused from the map frames"),
                 "--map": ("frames,render", "with `--frames`: the map images: the real map frames (`frames`), the "
                                            "fused surface rendered at their poses (`render`) or both"),
                 "--no-gap": ("off", "with `--frames`: skip the queries rendered from the fused surface (the gap "
                                     "table)"),
                 "--block": ("50", "with `--frames`: frames per block of the map / query split"),
                 "--gap-frames": ("10", "with `--frames`: frames left out at each end of a query block"),
                 "--map-step": ("2", "with `--frames`: every n-th frame of a map block is a map image"),
                 "--query-step": ("2", "with `--frames`: every n-th frame of a query block is a query"),
                 **_COMMON_RUN_OPTIONS},
    "study": {**_SCENE_RUN_OPTIONS,
              "--seed": ("0", "seeds the scene generator of built-ins and every evaluation of the study (as "
                              "`evaluate --seed`)"),
              "--out": None, **_COMMON_RUN_OPTIONS},
}
"""Options of ``plan``, ``evaluate`` and ``study`` that set no config field: where the inputs are, where
the outputs go and how the run behaves; flag -> (the docs' default, the docs' text), None for
either: from its ``--help``. Every other option is a config field's (:func:`setting`)."""
