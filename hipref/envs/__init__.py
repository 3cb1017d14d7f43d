"""The two tasks of the study, and their registration with gymnasium."""

import gymnasium as gym

if "hipref/DeskWiping-v0" not in gym.registry:
    gym.register(id="hipref/DeskWiping-v0", entry_point="hipref.envs.gym_envs:DeskWipingEnv")
    gym.register(id="hipref/Pushing-v0", entry_point="hipref.envs.gym_envs:PushingEnv")
