"""Learning and acting: PPO (``ppo``, one readable module) and its satellites: the networks and
their registry (``networks``), observation normalization (``normalizers``), checkpoint files
(``checkpoints``), what training learns and counts (``training_state``), the metrics log
(``logger``, ``quality_log``), the trained-policy loader (``trained_policy``) and the scripted
joystick policies with the same interface (``policies``)."""
