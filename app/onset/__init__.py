"""The onset workflow: the tracker that owns the [stability] table (tracker.py), the per-step screen
(screening.py), bisection of a crossing and the wrinkle count at the band's minimum (bisection.py), the
crossing record (crossing.py), what happens after a crossing (policy.py), the switch onto a branch
(branching.py), where a branch ends (contact.py) and the surface's short-wave check (surface.py)."""
