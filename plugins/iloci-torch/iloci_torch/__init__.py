"""iloci plugin: the ``torch-rnnpb`` PerceptualModel (RNNPB in PyTorch).

Light on import: torch is imported only when the model is built.
"""

from iloci import hookimpl
from iloci.params import RNNPBParams


@hookimpl
def iloci_register_perceptual_models(registry) -> None:
    registry.add("torch-rnnpb", "iloci_torch.rnnpb:TorchRNNPB", params=RNNPBParams,
                 requires=("torch",), install="pip install torch==2.13.0",
                 summary="RNNPB in PyTorch operations: hand-written batched closed-loop "
                         "BPTT, multi-start recognition (float32 results depend on the CPU; "
                         "native-rnnpb's do not)")
