"""The onset workflow: the tracker that owns the [stability] table (tracker.py), the per-step screen
(screening.py), bisection of a crossing (bisection.py), the crossing record (crossing.py), what happens
after a crossing (policy.py), and wrinkle counting (wrinkles.py)."""
