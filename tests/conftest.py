import os
import sys

# tests import the shared problem library as ``problems``
sys.path.insert(0, os.path.dirname(__file__))
os.environ.setdefault("MPLBACKEND", "Agg")
