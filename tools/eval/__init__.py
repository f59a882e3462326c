"""`aeb eval`, `aeb label` and `aeb train-verifier`: the paper's evaluation of a camera
verifier on labelled ROIs from recordings and public data sets (docs/evaluation.md).

Modules, one job each: records (the ROI set), recording (ROIs as fusion
builds them from a recording read with tools/recording), sim_truth (a simulator run's ground
truth), adapters (KITTI, View-of-Delft, the paper's ROI construction), depth (lidar depth
images, the D435 noise model), scoring (every verifier on the same ROIs), labels (the
label file), sampling and labelweb (the label tool), metrics, report, tables and plots
(the paper's tables and figures), runner (local processes or Dask), paper (the paper's
numbers, constructed), demo_recording (the demo scenarios, recorded), training and
train_verifier (`aeb train-verifier`: hog_linear fitted on labelled ROIs, and its
command line), options (values the command lines offer, importable without the eval
extra), evaluate (what `aeb eval` runs) and cli (its command line).
"""
