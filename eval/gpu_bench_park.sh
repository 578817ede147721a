#!/bin/bash
# Where a park test's time goes with learned:park on a machine with a GPU (hardware EGL), as eval/bench_park_step.py
# measures it on the 2-core CPU machine (software EGL). Made for the device machine, which starts bare with its own
# Python, torch and numpy: run it from the repository root with the wheels garage-mj needs for a park test in .whl/
# (mujoco, mujoco-core, mujoco-studio, glfw, PyOpenGL, dm-control, dm-env, gymnasium, farama-notifications,
# stable-baselines3, ompl; `pip download --no-deps --python-version 3.12 ...`), the GL loader packages in .gl/
# (libegl1, libglvnd0, libopengl0, libgl1, libglx0, libgles2: `apt-get download`), and OUT set to the folder that
# receives the JSON files:
#   OUT=/tmp/gpu bash eval/gpu_bench_park.sh
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
[ -f "$vendor" ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    2>&1 | tail -2
# the package data (maps, models) beside the package, without installing it
ln -sfn ../maps garage_mj/maps; ln -sfn ../models garage_mj/models
export PYTHONPATH=/tmp/site:$PWD MUJOCO_GL=egl PYTHONUNBUFFERED=1
nvidia-smi -L; nproc
python3 -c "import mujoco; m = mujoco.MjModel.from_xml_string('<mujoco/>'); r = mujoco.Renderer(m, 64, 64); \
print('mujoco', mujoco.__version__, 'renders', r.render().shape)" || exit 3
python3 eval/bench_park_step.py --garages 4 --tests 4 --geometries default tight parallel \
    --json "$OUT/park_step_gpu.json" 2>&1 | grep -E '"(tests|sim_s_per_wall_s|reset_ms_per_test|ceiling_env_only_sim_s_per_wall_s)"|Error'
python3 eval/bench_park_step.py --garages 4 --tests 4 --geometries default tight parallel --scenario park_mixed \
    --json "$OUT/park_step_gpu_actors.json" 2>&1 | grep -E '"(tests|sim_s_per_wall_s|reset_ms_per_test)"|Error'
