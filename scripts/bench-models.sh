# The robots of ../shared/models that the comparison scripts time (sourced by
# compare-pinocchio.sh and compare-builds.sh).
#
# name | base | contact frames (3D point contacts, for the contact algorithms;
# ../shared/models/README.md). The programs get --name = the URDF stem (sodyn bench would
# default to the robot name, e.g. "solo" for solo12.urdf), which the tables are keyed by.
# shellcheck disable=SC2034  # used by the scripts that source this file
MODEL_TABLE="
double_pendulum_continuous|fixed|
ur5_robot|fixed|
kinova|fixed|
panda|fixed|
baxter|fixed|
tiago|fixed|
solo12|ff|FL_FOOT,FR_FOOT,HL_FOOT,HR_FOOT
hyq_no_sensors|ff|lf_foot,rf_foot,lh_foot,rh_foot
anymal|ff|LF_FOOT,RF_FOOT,LH_FOOT,RH_FOOT
talos_reduced|ff|left_sole_link,right_sole_link
talos_full_v2|ff|left_sole_link,right_sole_link
"
