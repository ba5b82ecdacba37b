"""iloci plugin: the ``native-rnnpb`` PerceptualModel (RNNPB: float32 in a C kernel, else numpy).

Light on import: the kernel is loaded when a model is built.
"""

from iloci import hookimpl
from iloci.params import RNNPBParams


@hookimpl
def iloci_register_perceptual_models(registry) -> None:
    registry.add("native-rnnpb", "iloci_native.rnnpb:NativeRNNPB", params=RNNPBParams,
                 summary="RNNPB with float32 training, recognition and scoring in a C kernel "
                         "(AVX-512, AVX2 or portable: the same bits on every CPU), the numpy "
                         "reference for float64; no torch",
                 describe="iloci_native.native:describe")
