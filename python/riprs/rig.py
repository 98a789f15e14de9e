"""Seeded random rigs across the envelope riprs must handle, and the named rigs of the
tables of docs/tuning.md.

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

:func:`named_rig` gives those rigs by name (``rip_core::rig::NamedRig``), each read by the
tables' sensor, for the tests, benches and docs' tables to share:

>>> riprs.named_rig("heavy").params.mp
0.06
>>> riprs.named_rig("paper").to_config()["plant"]
{'preset': 'paper'}
"""

from __future__ import annotations

from riprs._riprs import NamedRig, Rig, named_rig, named_rigs, random_rig

__all__ = ["NamedRig", "Rig", "named_rig", "named_rigs", "random_rig"]
