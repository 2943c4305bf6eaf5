"""nav2_bt_navigator and nav2_behavior_tree.

Nav2's BT nodes (`control_nodes`, `leaves`, `tree_nodes`, registered by `factory`), the servers as
the leaves reach them (`action_servers`), `BtNavigator` (`navigator`) and its node (`bt_navigator_node`).
"""
