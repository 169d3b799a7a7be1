"""The paper's experiment: every (environment, method, seed) trained for the same wall-clock budget.

``grid``: what an experiment is (pure dataclasses, its trials and their run
dirs). ``bands``: means with BCa bootstrap bands (pure NumPy/SciPy).
``runner``: the Ray Tune shell that trains the trials and restores an
interrupted experiment. ``report``: the results figure and table.
"""
