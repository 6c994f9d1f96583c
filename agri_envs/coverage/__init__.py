"""GreenhouseCoverage: González et al. (2009), the tracked Fitorobot covering every corridor of a greenhouse."""
