"""Layer 1: SDF worlds and models, and the Scene the robot moves and scans in."""

from twin.world.sdf import load_model, load_world
from twin.world.types import Model, World

__all__ = ["Model", "World", "load_model", "load_world"]
