"""Stage package ``publish`` of the refine data flow (see DEVELOPERS.md)."""
