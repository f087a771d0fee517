"""bcad: a Bayesian robotic CAD system.

Data flows one way: problem file -> schema (:mod:`bcad.model`) -> kinematic graph
(:mod:`bcad.compile`) -> batched kinematics (:mod:`bcad.kinematics`) -> solver backend
(:mod:`bcad.solvers`) -> JSON result.
"""

__version__ = "0.1.0"
