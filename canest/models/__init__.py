"""Vehicle models: pure functions of state, input and time step, vectorized over points."""
