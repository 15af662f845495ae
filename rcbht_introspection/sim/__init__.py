"""MuJoCo snap-assembly simulator: the project's own wrench trials (pure: mujoco + numpy)."""

from rcbht_introspection.sim.config import SimConfig, load_sim_config
from rcbht_introspection.sim.dataset import write_dataset
from rcbht_introspection.sim.simulate import simulate_trial

__all__ = ["SimConfig", "load_sim_config", "simulate_trial", "write_dataset"]
