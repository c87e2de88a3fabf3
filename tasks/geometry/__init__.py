"""Stage package ``geometry`` of the refine data flow (see DEVELOPERS.md)."""
