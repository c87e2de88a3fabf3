"""Stage package ``interpret`` of the refine data flow (see DEVELOPERS.md)."""
