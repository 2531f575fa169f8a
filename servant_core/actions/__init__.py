"""What the arm does in each scene: teach records, and the learner from perceived scene to pose."""
