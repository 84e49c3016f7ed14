"""Homing and calibration: the record of where each encoder reads zero, how it is found
(``cdprctl calibrate known-pose`` and ``self``) and how ``cdprctl run`` checks it at start-up
(docs/homing.md)."""
