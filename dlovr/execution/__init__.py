"""Running compiled programs in simulation: force-guarded macros, scene variation and trials."""
