"""atlasnn.systems._hamiltonian."""
