"""dlovr: virtual-reality demonstrations of deformable linear object (DLO) manipulation.

The data flows one way: scene -> simulation -> contacts -> topology -> discrete -> transitions ->
program. The model modules (:mod:`dlovr.topology`, :mod:`dlovr.discrete`, :mod:`dlovr.transitions`)
are pure Python + numpy.
"""

__version__ = "0.1.0"
