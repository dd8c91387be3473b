"""hydrobuckle: swelling-induced wrinkling of constrained hydrogels.

A two-field (displacement, fluid-volume flux) incremental minimization principle for finite
elasticity coupled with Fickian diffusion, discretized with Q1 x RTCF elements on FEniCSx, with
a stability analysis of the coupled Hessian to locate the onset of wrinkling.
"""

__version__ = "0.1.0"
