"""Demonstrations: the LASA data set, user trajectory files, the concept map."""

from iloci.data.concepts import LASA_CONCEPTS, LASA_SHAPES, MULTI_MODEL_SHAPES, concept_of
from iloci.data.files import load_trajectory
from iloci.data.lasa import DEMOS_PER_SHAPE, lasa_directory, load_lasa
from iloci.data.streams import default_stream, resolve_demo, resolve_demos
from iloci.interfaces import Demonstration

__all__ = ["Demonstration", "DEMOS_PER_SHAPE", "LASA_CONCEPTS", "LASA_SHAPES",
           "MULTI_MODEL_SHAPES", "concept_of", "default_stream", "lasa_directory",
           "load_lasa", "load_trajectory", "resolve_demo", "resolve_demos"]
