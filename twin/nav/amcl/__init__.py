"""nav2_amcl: the particle filter and likelihood field (`filter`, C in `amcl_kernels.c`), its nodes (`amcl_node`)."""
