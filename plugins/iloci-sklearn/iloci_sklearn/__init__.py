"""iloci plugin: the ``sklearn`` Clusterer (complete link, AgglomerativeClustering)."""

from iloci import hookimpl


@hookimpl
def iloci_register_clusterers(registry) -> None:
    registry.add("sklearn", "iloci_sklearn.clusterer:SklearnClusterer",
                 requires=("sklearn",), install="pip install ./plugins/iloci-sklearn",
                 summary="complete-link clustering, sklearn AgglomerativeClustering")
