"""Force-dependent kinematics (paper Fig. 1): find the FDK DOFs α of each frame where the
FDK residual forces vanish. Entry point: :func:`openfdk.fdk.analysis.run_fdk`."""
