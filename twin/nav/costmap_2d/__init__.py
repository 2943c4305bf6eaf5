"""nav2_costmap_2d: the grid and cost values (`costmap_2d`), the layered costmap and its layers (`layered_costmap`).

The footprint and its collision check are in `footprint`, the node in `costmap_node`, the C
kernels in `costmap_kernels.c`.
"""
