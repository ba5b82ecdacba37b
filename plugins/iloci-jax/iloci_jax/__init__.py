"""iloci plugin: the ``jax-rnnpb`` PerceptualModel (RNNPB in JAX).

Light on import: JAX is imported only when the model is built.
"""

from iloci import hookimpl
from iloci.params import RNNPBParams


@hookimpl
def iloci_register_perceptual_models(registry) -> None:
    registry.add("jax-rnnpb", "iloci_jax.rnnpb:JaxRNNPB", params=RNNPBParams,
                 requires=("jax",), install="pip install 'jax>=0.4.30' 'jaxlib>=0.4.30'",
                 summary="RNNPB in JAX: jit-compiled closed-loop BPTT, batched multi-start "
                         "recognition")
