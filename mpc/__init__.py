"""Game-theoretic MPC for several robots: dynamics, costs, NLPs, CMPC (Alg. 1), DMPC (Alg. 2)."""
