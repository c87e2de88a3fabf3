"""Stage package ``assemble`` of the refine data flow (see DEVELOPERS.md)."""
