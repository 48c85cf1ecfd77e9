"""Measuring controllers: the references a policy is read against (:mod:`mmrl.eval.reference`,
the equal-speed joystick line). The episode loops (:mod:`mmrl.rollout`) belong to this room
too and sit at its level of the layering (tests/test_layout.py)."""
