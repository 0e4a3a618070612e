"""Pictures: plan and elevation views, time plots, 3-D renders, their index and palette."""
