"""Drawing only: Rerun recordings, report markdown and PNG figures. Computes nothing."""
