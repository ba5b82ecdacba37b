"""iloci plugin: the ``sklearn`` Clusterer (complete link, AgglomerativeClustering)."""

from iloci import hookimpl


@hookimpl
def iloci_register_clusterers(registry) -> None:
    registry.add("sklearn", "iloci_sklearn.clusterer:SklearnClusterer",
                 requires=("sklearn",), install="pip install 'scikit-learn>=1.3'",
                 summary="complete-link clustering, sklearn AgglomerativeClustering")
