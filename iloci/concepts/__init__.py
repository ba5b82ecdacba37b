"""The paper's high-level module: memory, learner, rehearsal, clustering."""
