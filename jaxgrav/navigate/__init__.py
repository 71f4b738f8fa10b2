"""Voyage navigation: map-aided INS over hours.

Loosely coupled (matcher fixes as position measurements of the INS error Kalman
filter) and tightly coupled (the gravity filters on the readings directly) navigation
over a :class:`~jaxgrav.sim.voyage_log.Voyage`.
"""

__all__: list[str] = []
