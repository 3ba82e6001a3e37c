"""assess: judging what was identified, after the fit and the loop, before the report.

* :mod:`~vibid.identify.assess.stage`: the pipeline's assess stage, :func:`assess`, which
  runs the parts below on one result into one :class:`Assessment` (the report formats it);
* :mod:`~vibid.identify.assess.engineering`: engineering constants (E, ν, G; E1, E2, G12,
  ν12) from the bending stiffnesses and the thickness;
* :mod:`~vibid.identify.assess.budget`: their uncertainty budget, as the GUM writes one;
* :mod:`~vibid.identify.assess.plausibility`: physically possible, and like its material?
* :mod:`~vibid.identify.assess.reference`: a reference specimen calibrates the clamp;
* :mod:`~vibid.identify.assess.linearity`: is a measured resonance a linear structure's?
* :mod:`~vibid.identify.assess.curve`: the identified model's AFC on a fine grid, which the
  report's AFC figure and the live view draw.
"""

from vibid.identify.assess.stage import Assessment, FreeLengthShare, assess, reference_block

__all__ = ["Assessment", "FreeLengthShare", "assess", "reference_block"]
