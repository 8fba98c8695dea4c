from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("selfas-graph")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.4.3.dev1+source"
