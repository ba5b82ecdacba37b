"""The RNNPB that every back end computes: definition, checks, state, numpy reference.

* :mod:`iloci.rnnpb.common`: the model's definition (its docstring) and the
  shared front end :class:`RNNPBBase`; with :mod:`iloci.rnnpb.inputs` (input
  checks, padding) and :mod:`iloci.rnnpb.state` (the weights' layout, the PB
  reparametrisation, the state format), whose names it re-exports;
* :mod:`iloci.rnnpb.reference`: the forward pass and the whole training
  step (BPTT, clipping, schedule, Adam) in plain numpy, what the back ends'
  kernels are tested against; its float32 mode, :mod:`iloci.rnnpb.float32`,
  states native-rnnpb's float32 arithmetic (the same bits as its C kernel).

Numpy only: back ends (``torch-rnnpb``, ``jax-rnnpb``) are plugins.
"""

from iloci.rnnpb.common import *  # noqa: F401,F403
from iloci.rnnpb.common import __all__ as _common
from iloci.rnnpb.reference import (reference_generate, reference_outputs,
                                   reference_prediction_error)

__all__ = [*_common, "reference_outputs", "reference_prediction_error", "reference_generate"]
