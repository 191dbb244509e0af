"""Bottom layer shared by every stage: the scenario model and its loader, expressions,
follower models, graph algebra, errors and artifacts. It imports no other package of
the project."""
