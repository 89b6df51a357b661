// What a config trains on, named by KITTI raw drive: shared by training (data/training_data.h, which
// reads the frames) and evaluation (which warns when a model's training drives hold test data).
// GeoNet keeps each task's training data disjoint from its test set: depth on eigen_zhou without the
// Eigen test scenes, flow on raw without the KITTI 2015 scenes, pose on odometry 00-08.
#pragma once

#include "core/config.h"

#include <set>
#include <string>
#include <vector>

namespace geo {

// The lists of a KITTI raw split (every data.split but odometry) and what is left out of them.
struct RawTrainingLists {
  std::string train_list, val_list;     // val_list: "" when there is none
  bool from_drives = false;             // kitti_raw_stereo: training snippets from every drive on disk
                                        // (raw_drive_snippets); train_list then only names the root
  std::set<std::string> test_scenes;    // drives left out: the Eigen test scenes, and for
                                        // raw_minus_kitti2015 also KITTI 2015's (stereo/test_scenes_stereo.txt);
                                        // kitti_raw_stereo only KITTI 2015's
  std::set<std::string> static_frames;  // static_key()s left out (configs/splits/static_frames.txt;
                                        // none with data.remove_static false)
  std::vector<std::string> exclusions;  // the files those come from
};
// `root`: the raw folder (data.root resolved). Throws ConfigError naming data.train_list when there is
// no training list.
RawTrainingLists raw_training_lists(const DataConfig& data, const std::string& root);

// The KITTI raw drive an odometry sequence 00-10 was recorded in ("2011_09_30_drive_0033" for 09;
// KITTI odometry's readme), "" for any other sequence.
std::string odometry_raw_drive(const std::string& sequence);

// The KITTI raw drives ("2011_09_26_drive_0005") whose frames a config trains or validates on.
// `unknown` says why they cannot be told (a packed cache; a list that is not on this machine); the
// synthetic world rendered in memory holds no KITTI drive (an empty set).
struct TrainingDrives {
  std::set<std::string> drives;
  std::string unknown;
};
TrainingDrives training_drives(const DataConfig& data);

}  // namespace geo
