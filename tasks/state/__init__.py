"""Stage package ``state`` of the refine data flow (see DEVELOPERS.md)."""
