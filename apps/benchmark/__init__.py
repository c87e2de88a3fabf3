"""Stage package ``benchmark`` of the refine data flow (see DEVELOPERS.md)."""
