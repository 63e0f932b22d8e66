"""The plant (floor 2): the linear system ``x[k+1] = A x[k] + B u[k]`` and its identification with physics.
"""

from workbench.exports import lazy_exports

_EXPORTS = {
    "IdentificationReport": "identification",
    "PhysicalCheck": "physics",
    "StickResponse": "physics",
    "identify_plant": "identification",
    "choose_plant": "choice",
    "plant_rule": "choice",
    "resolve_structure": "identification",
    "LinearSystem": "system",
    "planar_quadrotor": "system",
    "is_stabilizable": "system",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
