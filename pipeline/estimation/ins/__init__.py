"""The INS/GNSS family: loosely and tightly coupled EKF and UKF (with and without the non-holonomic
constraints) of paper 001 and the fuzzy-adaptive weighted EKF of paper 004.

``run`` is the family under the run contract; ``replay`` prepares the inputs (``inputs``),
aligns (``alignment``) and drives the compiled kernels (``kernels``) over the models
(``models``) or filterpy (``reference``, ``reference_fwekf``); ``outputs``, ``metrics``,
``truth`` and ``tracks`` turn a run into its tables, metrics and error track; ``config`` types
the filters' sections, ``fuzzy`` is paper 004's weighting.
"""
