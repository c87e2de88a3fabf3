"""Stage package ``tune`` of the refine data flow (see DEVELOPERS.md)."""
