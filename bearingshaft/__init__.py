"""bearingshaft: the command line, scenes and pipeline that join geometry, fem and reduced."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bearingshaft")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0+unknown"
