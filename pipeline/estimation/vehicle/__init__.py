"""The vehicle-model family of paper 003: kinematic, dynamic, switched and IMM EKFs over wheel
speed, steering and GNSS fixes.

``run`` is the family under the run contract; ``replay`` prepares the inputs and drives the
compiled kernel (``kernel``) over the models (``model``) or filterpy (``reference``);
``metrics`` measures a run; ``config`` types the filters' sections.
"""
