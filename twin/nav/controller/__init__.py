"""nav2_controller: controller_server (`controller_server`, `checkers`), DWB (`dwb`), RPP (`regulated_pure_pursuit`)."""
