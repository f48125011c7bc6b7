"""The one tick every runner calls: world step, radio step, agent step, referee (docs/architecture.md)."""
