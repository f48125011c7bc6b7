"""Vehicle kinds as plug-ins (docs/architecture.md, "Vehicle kinds")."""
