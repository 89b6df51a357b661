#!/bin/sh
# From a clip to a trained model with the shipped video config: geo_synth writes a drive as a
# Motion-JPEG video, geo_train trains on the video file, then on a frame folder (the same drive's
# PNGs, with a field of view instead of intrinsics), and geo_infer runs on the video.
#   video_training.sh <apps dir> <work dir>
set -eu
apps="$1"
work="$2"
data="${3:-$(dirname "$0")/../data}"
rm -rf "$work"
mkdir -p "$work"
"$apps/geo_synth" --preset tiny --drives 1 --test-drives 1 --frames 24 --flow-pairs 0 --odometry-frames 5 \
  --out "$work/world" --video "$work/drive.avi" > "$work/synth.log" 2>&1
grep -q "train with --set data.videos=\[$work/drive.avi\]" "$work/synth.log"
small="model.encoder_depth=18 data.height=64 data.width=208 stages.0.iterations=2 stages.0.batch_size=2 \
       data.num_workers=1 logging.interval=1 logging.val_interval=2 logging.checkpoint_interval=2"
# A video file with the camera the world was rendered with (geo_synth printed it).
"$apps/geo_train" --config video.yaml --run-dir "$work/run_video" --set "data.videos=[$work/drive.avi]" \
  --set "data.camera.intrinsics=[120.8,123.1,102.1,29.5]" --set data.video.val_fraction=0.2 --set $small \
  > "$work/video.log" 2>&1 || { cat "$work/video.log"; exit 1; }
# What was kept and why is printed: 24 frames at 10 fps, none static, 5 in a validation block.
grep -q "clip '$work/drive.avi': 24 frames (208x64, 10 fps); every frame, 0 static frames left out" "$work/video.log" ||
  { cat "$work/video.log"; exit 1; }
grep -q "validation snippets in 1 block" "$work/video.log" || { cat "$work/video.log"; exit 1; }
test -f "$work/run_video/checkpoints/stage1-00000002.pt"
# A frame folder with only a field of view.
frames=$(ls -d "$work"/world/raw/*/*_drive_0001_sync/image_02/data)
"$apps/geo_train" --config video.yaml --run-dir "$work/run_frames" --set "data.videos=[$frames]" \
  --set data.camera.fov_deg=81 --set $small > "$work/frames.log" 2>&1 || { cat "$work/frames.log"; exit 1; }
grep -q "clip '$frames': 24 frames (208x64, rate unknown)" "$work/frames.log" || { cat "$work/frames.log"; exit 1; }
test -f "$work/run_frames/checkpoints/stage1-00000002.pt"
# A frame folder without any camera: the networks learn it (the resolved config says so).
"$apps/geo_train" --config video.yaml --run-dir "$work/run_learned" --set "data.videos=[$frames]" \
  --set $small > "$work/learned.log" 2>&1 || { cat "$work/learned.log"; exit 1; }
grep -q "camera not given: learned by the networks" "$work/learned.log" || { cat "$work/learned.log"; exit 1; }
grep -q "stage1 2/2 .* | camera fx [0-9.]* fy [0-9.]* cx [0-9.]* cy [0-9.]*" "$work/learned.log" || { cat "$work/learned.log"; exit 1; }
grep -q "learn_intrinsics: true" "$work/run_learned/config.yaml"
test -f "$work/run_learned/checkpoints/stage1-00000002.pt"
"$apps/geo_infer" --checkpoint "$work/run_learned" --input "$frames" --output "$work/infer_learned" --max-frames 3 \
  > "$work/infer_learned.log" 2>&1 || { cat "$work/infer_learned.log"; exit 1; }
grep -q "learned camera" "$work/infer_learned.log" || { cat "$work/infer_learned.log"; exit 1; }
# A ground truth without motion is refused before anything is computed or written.
for i in 1 2 3 4; do echo "1 0 0 0 0 1 0 0 0 0 1 0"; done > "$work/still_poses.txt"
if "$apps/geo_infer" --checkpoint "$work/run_video" --input "$work/drive.avi" --output "$work/infer_still" --max-frames 4 \
  --ground-truth "$work/still_poses.txt" > "$work/infer_still.log" 2>&1; then
  echo "a motionless --ground-truth was accepted"; exit 1
fi
grep -q "no motion over the input's 4 frames" "$work/infer_still.log" || { cat "$work/infer_still.log"; exit 1; }
test ! -e "$work/infer_still"
# geo_infer on the video.
"$apps/geo_infer" --checkpoint "$work/run_video" --input "$work/drive.avi" --output "$work/infer" --max-frames 4 \
  > "$work/infer.log" 2>&1 || { cat "$work/infer.log"; exit 1; }
test -f "$work/infer/000003-depth.png"
test -f "$work/infer/trajectory.txt"
# Real frames (grey PNGs of a KITTI odometry run), no camera: the networks learn it.
real="$data/kitti_real/odometry_forward/frames"
"$apps/geo_train" --config video.yaml --run-dir "$work/run_real" --set "data.videos=[$real]" \
  --set $small > "$work/real.log" 2>&1 || { cat "$work/real.log"; exit 1; }
grep -q "clip '$real': 51 frames (424x128, rate unknown)" "$work/real.log" || { cat "$work/real.log"; exit 1; }
grep -q "camera not given: learned by the networks" "$work/real.log" || { cat "$work/real.log"; exit 1; }
test -f "$work/run_real/checkpoints/stage1-00000002.pt"
# Passed: its checkpoints (a gigabyte) go; GEO_KEEP_TEST_DIRS=1 keeps them.
[ "${GEO_KEEP_TEST_DIRS:-}" = 1 ] || rm -rf "$work"
echo "video training: ok"
