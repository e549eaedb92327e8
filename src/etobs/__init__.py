"""etobs: decentralized event-triggered state estimation of nonlinear systems."""
