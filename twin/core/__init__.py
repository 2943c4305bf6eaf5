"""Layer 0: the integer clock, SE(2)/SE(3) helpers, the error hierarchy and the config loader.

Import the modules directly: `twin.core.clock`, `twin.core.geometry`, `twin.core.errors`,
`twin.core.config`.
"""

from twin.core.clock import NS_PER_S
from twin.core.errors import ConfigError, TwinError

__all__ = ["NS_PER_S", "ConfigError", "TwinError"]
