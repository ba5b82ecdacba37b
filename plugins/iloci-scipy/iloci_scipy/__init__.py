"""iloci plugin: the ``scipy`` Clusterer (complete link, scipy.cluster.hierarchy)."""

from iloci import hookimpl


@hookimpl
def iloci_register_clusterers(registry) -> None:
    registry.add("scipy", "iloci_scipy.clusterer:ScipyClusterer", requires=("scipy",),
                 install="pip install 'scipy>=1.10'",
                 summary="complete-link clustering, scipy linkage/fcluster")
