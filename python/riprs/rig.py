"""Seeded random rigs across the envelope riprs must handle.

:func:`random_rig` draws a full parameter set (masses, lengths, inertias, motor, viscous and
Coulomb friction, dead zone) and its sensors (encoder counts, angle noise) from a seed, in the
form a configuration file's ``[plant]`` and ``[sensor]`` sections take: the one generator the
tests of unknown rigs share (``rip_core::rig`` documents the ranges and their draws).

Examples
--------
>>> import riprs
>>> rig = riprs.random_rig(3)
>>> rig == riprs.random_rig(3)
True
>>> 512 <= rig.encoder_counts[0] <= 8192
True
"""

from __future__ import annotations

from riprs._riprs import Rig, random_rig

__all__ = ["Rig", "random_rig"]
