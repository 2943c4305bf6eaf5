"""nav2_map_server: the occupancy map (`map_io`: load, save, made from the world) and `MapServerNode`."""
