"""iloci plugin: the ``native-rnnpb`` PerceptualModel (RNNPB: float32 in a C kernel, else numpy).

Light on import: the kernel is loaded when a model is built.
"""

from dataclasses import dataclass

from iloci import hookimpl
from iloci.params import RNNPBParams


@dataclass(frozen=True)
class NativeRNNPBParams(RNNPBParams):
    """:class:`~iloci.params.RNNPBParams`, with native-rnnpb's kernels checked when the
    config is (``iloci config check``), not when the model is built."""

    def validate(self) -> None:
        super().validate()
        if self.kernel == "torch":
            raise ValueError('kernel = "torch" names torch-rnnpb\'s torch operations; '
                             'native-rnnpb runs kernel = "auto" or "native" (or set '
                             '[perceptual_model] name = "torch-rnnpb")')


@hookimpl
def iloci_register_perceptual_models(registry) -> None:
    registry.add("native-rnnpb", "iloci_native.rnnpb:NativeRNNPB", params=NativeRNNPBParams,
                 summary="RNNPB with float32 training, recognition and scoring in a C kernel "
                         "(AVX-512, AVX2 or portable: the same bits on every CPU), the numpy "
                         "reference for float64; no torch",
                 describe="iloci_native.native:describe")
