"""nav2_behaviors: Spin, BackUp and DriveOnHeading, Wait, on `TimedBehavior`; `BehaviorServer` and its node."""
