"""Demonstrations: the LASA data set, user trajectory files, the concept map."""

from iloci.data.concepts import LASA_CONCEPTS, LASA_SHAPES, MULTI_MODEL_SHAPES, concept_of
from iloci.interfaces import Demonstration

__all__ = ["Demonstration", "LASA_CONCEPTS", "LASA_SHAPES", "MULTI_MODEL_SHAPES",
           "concept_of"]
