"""Shipped data of the ``power_grid`` family: one JSON file per ANDES case, written by :mod:`.generate`.

The family (:mod:`compare.run.families.power_grid`) reads these files with the standard
library only; ANDES is needed only to regenerate them
(``pip install -e .[power]``, then ``python -m compare.run.families.power_cases.generate``).
"""
