"""Stage package ``check`` of the refine data flow (see DEVELOPERS.md)."""
