"""The physics: material laws, the incremental potential, loadings, and the discrete problem.

The built-in material laws are registered here (a new law: its module plus one line below)."""

from app.model.hydrogel import HYDROGEL
from app.model.material import LAWS

LAWS.register(HYDROGEL)
DEFAULT_LAW = "hydrogel"
