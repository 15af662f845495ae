"""MuJoCo snap-assembly simulator: the project's own wrench trials."""
