"""The closed loop offline: the simulated robot, the verifier and the reference planner in one
process, for statistics over many trials (`rcbht closed-loop`)."""
