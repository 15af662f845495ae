"""MuJoCo simulator of contact tasks (the HIRO snap assembly, a peg-in-hole): the project's own
wrench trials (pure: mujoco + numpy)."""

from rcbht_introspection.sim.config import SimConfig, load_sim_config
from rcbht_introspection.sim.dataset import write_dataset
from rcbht_introspection.sim.peg_config import PegConfig, load_peg_config
from rcbht_introspection.sim.peg_controller import PEG_TASK
from rcbht_introspection.sim.peg_simulate import simulate_peg_trial
from rcbht_introspection.sim.simulate import simulate_trial
from rcbht_introspection.sim.tasks import SIM_TASKS, SimTaskName, load_task_config

__all__ = [
    "PEG_TASK",
    "SIM_TASKS",
    "PegConfig",
    "SimConfig",
    "SimTaskName",
    "load_peg_config",
    "load_sim_config",
    "load_task_config",
    "simulate_peg_trial",
    "simulate_trial",
    "write_dataset",
]
