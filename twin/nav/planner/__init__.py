"""nav2_planner's planner_server (`planner_server`) and nav2_navfn_planner's NavFn (`navfn`, C in `navfn_kernels.c`)."""
