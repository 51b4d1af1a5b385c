"""The core layer: the robot, the tank, collision, configuration, files and errors.

Nothing here imports another layer of the package; everything else builds on it
(the layers: docs/design.md §1).
"""
