"""The matching pipeline: its configuration, the match state, the stage runner and the stages."""
