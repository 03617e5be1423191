"""What every layer builds on: typed config errors, option dataclasses, name registries,
fixed-order arithmetic, atomic files and pytree checkpoints. Imports nothing else of the
package (host workers import it without JAX)."""
