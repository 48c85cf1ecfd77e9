"""Bridges to other frameworks: Ray RLlib's PPO on mmrl's envs (:mod:`mmrl.integrations.rllib`)."""
