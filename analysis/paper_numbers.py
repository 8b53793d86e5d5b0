"""The published numbers live in the package (train scripts print them too): ``hnn.paper``."""
from hnn.paper import PAPER  # noqa: F401
