"""The simulation the planner and the testbed share: renders of a scene with a placement's
tags, localizations of those images against the map, and the success model fitted on them
(``plan``'s calibration of ``expected-recall``, ``evaluate``'s predictions)."""
