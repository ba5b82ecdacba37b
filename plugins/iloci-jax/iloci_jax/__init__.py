"""iloci plugin: the ``jax-rnnpb`` PerceptualModel (RNNPB in JAX).

Light on import: JAX is imported only when the model is built.
"""

from dataclasses import dataclass

from iloci import hookimpl
from iloci.params import RNNPBParams


@dataclass(frozen=True)
class JaxRNNPBParams(RNNPBParams):
    """:class:`~iloci.params.RNNPBParams`, with jax-rnnpb's one kernel checked when the
    config is (``iloci config check``), not when the model is built."""

    def validate(self) -> None:
        super().validate()
        if self.kernel != "auto":
            raise ValueError(_ONE_KERNEL.format(kernel=self.kernel))


#: jax-rnnpb's answer to a ``kernel`` it does not have.
_ONE_KERNEL = ("jax-rnnpb has one kernel (XLA's), got kernel = {kernel!r}; remove the "
               "setting or set kernel = \"auto\" (\"native\" is native-rnnpb's C kernel, "
               "\"torch\" torch-rnnpb's torch operations)")


@hookimpl
def iloci_register_perceptual_models(registry) -> None:
    registry.add("jax-rnnpb", "iloci_jax.rnnpb:JaxRNNPB", params=JaxRNNPBParams,
                 requires=("jax",), install="pip install 'jax>=0.4.30' 'jaxlib>=0.4.30'",
                 summary="RNNPB in JAX: jit-compiled closed-loop BPTT, batched multi-start "
                         "recognition")
