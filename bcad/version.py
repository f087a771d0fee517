"""bcad's version: a leaf module, so that nothing inside the package imports the package root."""

__version__ = "0.1.0"
