"""Quasi-static mechanics of peg-hole extraction (thesis Ch 2-3).

* :mod:`.planar` - the planar two-point template: exact geometry, re-derived boundary
  quadratics and contact forces shared by every 2D category;
* :mod:`.dual` - dual peg-hole, categories 5, 10, 9 (eqs 2.7-2.49);
* :mod:`.rect` - rectangular peg-hole, cases 1-5 (eqs 3.1-3.118);
* :mod:`.oracle` - independent exact quasi-static contact solver (the numerical oracle);
* :mod:`.jamming` - jamming parallelogram (eqs 2.50-2.52) and the exact static test;
* :mod:`.states` - contact-state enumeration (claims C2.1, C3.1);
* :mod:`.figures`, :mod:`.claims`, :mod:`.cli` - the ``peghole analyze`` command.

Extractability (eqs 2.1-2.3 and ``w' < w, v' < v``) lives in
:mod:`peghole_mjx.geometry.specs` and is re-exported here.
"""

from peghole_mjx.analysis.common import THETA0_RAD, rest_pose
from peghole_mjx.analysis.dual import two_point_region as dual_two_point_region
from peghole_mjx.analysis.rect import edge_contact as rect_edge_contact
from peghole_mjx.analysis.rect import two_contact_region as rect_two_contact_region
from peghole_mjx.geometry.specs import (
    InfeasibleGeometryError,
    check_dual_extractable,
    check_rect_extractable,
)

__all__ = [
    "THETA0_RAD",
    "InfeasibleGeometryError",
    "check_dual_extractable",
    "check_rect_extractable",
    "dual_two_point_region",
    "rect_edge_contact",
    "rect_two_contact_region",
    "rest_pose",
]
