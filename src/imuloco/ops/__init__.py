"""Pure array functions shared by every stage: rotations, kinematics, heading frames, filters."""
