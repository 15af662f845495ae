"""The reference planner, pure Python: the recovery table and the policies that turn verdicts
and attempt results into attempts, aborts and corrections (planner_node, `rcbht closed-loop`)."""
