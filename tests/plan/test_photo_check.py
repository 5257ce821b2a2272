"""What `check --photos` tells the person with the phone: planned tags no photo saw, tags that
need more views."""

from __future__ import annotations

import numpy as np

from markerplace.markers import Marker
from markerplace.plan.photo_check import PhotoSurvey, PhotoTag, guidance


def test_guidance_names_unseen_spots_and_tags_needing_views():
    planned = [Marker(t, 0.4, np.eye(4)) for t in (1, 2, 3, 4)]
    tags = {1: PhotoTag(1, np.eye(4), 0.004, 0.3, 6, (0, None), True),
            2: PhotoTag(2, np.eye(4), 0.004, 0.3, 1, (0, None), False, "seen in 1 photo; take one more"),
            9: PhotoTag(9, None, None, None, 3, (0, None), False, "its photos share no tag with the photos placed")}
    planned.append(Marker(5, 0.4, np.eye(4)))
    survey = PhotoSurvey(tags, {0: np.eye(4)}, [[1, 2]], {3: 0, 4: 2, 5: -1}, unplaced_photos=[5, 6])
    lines = guidance(survey, planned)
    assert lines[0].startswith("the spot(s) of planned tag(s) 5 show another tag")  # a photo saw a tag there
    assert lines[1].startswith("no photo saw planned tag(s) 3:")  # 4 was looked at by 2 photos: missing, not unseen
    assert "tag 2 needs more views: seen in 1 photo" in lines[2] and "tag 9 needs more views" in lines[3]
    assert lines[4].startswith("2 photo(s) could not be placed")
    assert guidance(PhotoSurvey({1: tags[1]}, {}, [[1]], {}), planned[:1]) == []
