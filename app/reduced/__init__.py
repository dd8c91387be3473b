"""The exact 1D reduction of the laterally uniform bilayer and the axisymmetric tube.

While it has not buckled, the bilayer swells in a state that depends on the thickness coordinate Y only
(F = diag(1, lambda(Y, t)), flux along Y) and the circular tube in an axisymmetric one (F = diag(1 + u',
1 + u/r) in polar axes). The second variation about such a state separates into Fourier modes (sin/cos
k x along the bilayer, cos/sin n theta around the tube), so both the transient and its stability under
each criterion are 1D problems: :mod:`section` (the cross-section from a config), :mod:`transient` (the
swelling in time, from the same material law and incremental potential as the 2D model), :mod:`modes`
(each wavenumber's stiffness and the short-wave limit of the surface) and :mod:`onset` (the margin curve:
the critical time of every mode, g_c, N_c).
"""
