"""dwb_core, dwb_plugins and dwb_critics: DWB's local planner (`local_planner`, its cycle in C in `dwb_kernel.c`)."""
