"""Vision for the distilled student (paper Sec. III-D, issue 42): egocentric depth in simulation
(:mod:`train.vision.camera`)."""
