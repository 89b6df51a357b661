// Results files (eval/protocols.h): EvalResult as JSON, read back, and printed side by side.
#include "eval/protocols.h"

#include "core/logging.h"
#include "data/text_io.h"

#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace geo {

std::string EvalResult::json() const {
  std::ostringstream s;
  s.precision(9);
  auto q = [](const std::string& x) {
    std::string out = "\"";
    for (char c : x) out += (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
    return out + "\"";
  };
  s << "{\n  \"split\": " << q(split) << ",\n  \"source\": " << q(source) << ",\n  \"data_root\": " << q(data_root);
  if (!scaling.empty()) s << ",\n  \"scaling\": " << q(scaling);
  if (!precision.empty()) s << ",\n  \"precision\": " << q(precision);
  if (!subset.empty()) s << ",\n  \"subset\": " << q(subset);
  s << ",\n  \"metrics\": {";
  for (size_t i = 0; i < metrics.size(); ++i) {  // JSON has no NaN/Inf: a non-finite metric is null
    s << (i ? ", " : "") << q(metrics[i].first) << ": ";
    if (std::isfinite(metrics[i].second)) s << metrics[i].second;
    else s << "null";
  }
  s << "},\n  \"counts\": {";
  for (size_t i = 0; i < counts.size(); ++i) s << (i ? ", " : "") << q(counts[i].first) << ": " << counts[i].second;
  s << "}";
  auto list = [&](const char* key, const std::vector<std::string>& items) {
    s << ",\n  \"" << key << "\": [";
    for (size_t i = 0; i < items.size(); ++i) s << (i ? ", " : "") << q(items[i]);
    s << "]";
  };
  list("test_drives", test_drives);
  list("test_drives_in_training", test_drives_in_training);
  if (!training_drives_unknown.empty()) s << ",\n  \"training_drives_unknown\": " << q(training_drives_unknown);
  s << "\n}\n";
  return s.str();
}

EvalResult read_result(const std::string& path) {
  YAML::Node n;
  try {
    n = YAML::LoadFile(path);
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot read results '" + path + "': " + e.what());
  }
  const auto not_results = [&](const std::string& why) {
    return std::runtime_error("'" + path + "' is not a geo_eval results file (--output of geo_eval): " + why);
  };
  if (!n.IsMap()) throw not_results("not a JSON object");
  for (const char* key : {"split", "metrics", "counts"})
    if (!n[key]) throw not_results(std::string("no '") + key + "'");
  EvalResult r;
  try {
    r.split = n["split"].as<std::string>();
    r.source = n["source"].as<std::string>("");
    r.data_root = n["data_root"].as<std::string>("");
    r.scaling = n["scaling"].as<std::string>("");
    r.precision = n["precision"].as<std::string>("");
    r.subset = n["subset"].as<std::string>("");
    if (!n["metrics"].IsMap() || !n["counts"].IsMap())
      throw std::runtime_error("'metrics' and 'counts' must be objects");
    for (const auto& kv : n["metrics"])
      r.metrics.emplace_back(kv.first.as<std::string>(),
                             kv.second.IsNull() ? std::numeric_limits<double>::quiet_NaN() : kv.second.as<double>());
    for (const auto& kv : n["counts"]) r.counts.emplace_back(kv.first.as<std::string>(), kv.second.as<int64_t>());
    for (const auto& d : n["test_drives"]) r.test_drives.push_back(d.as<std::string>());
    for (const auto& d : n["test_drives_in_training"]) r.test_drives_in_training.push_back(d.as<std::string>());
    r.training_drives_unknown = n["training_drives_unknown"].as<std::string>("");
  } catch (const std::exception& e) {
    throw not_results(e.what());
  }
  if (r.split != "eigen" && r.split != "kitti2015" && r.split != "odometry")
    throw not_results("unknown split '" + r.split + "'");
  if (r.metrics.empty() || r.counts.empty()) throw not_results("no metrics or no counts");
  return r;
}

std::string format_results(const std::vector<EvalResult>& results, const std::vector<std::string>& names) {
  std::ostringstream s;
  std::vector<std::string> keys;
  for (const auto& r : results)
    for (const auto& m : r.metrics)
      if (std::find(keys.begin(), keys.end(), m.first) == keys.end()) keys.push_back(m.first);
  // Columns of 14 characters, wider where a name is longer (names are shown whole).
  size_t width = 14;
  for (const auto& n : names) width = std::max(width, n.size());
  const auto column = [width](const std::string& n) { return fmt::format(" {:>{}}", n, width); };
  s << fmt::format("{:<22}", "metric");
  for (const auto& n : names) s << column(n);
  s << "\n";
  for (const auto& k : keys) {
    s << fmt::format("{:<22}", k);
    for (const auto& r : results) {
      auto it = std::find_if(r.metrics.begin(), r.metrics.end(), [&](const auto& m) { return m.first == k; });
      s << (it == r.metrics.end() ? column("-") : fmt::format(" {:>{}.4f}", it->second, width));
    }
    s << "\n";
  }
  // What each column scored: the protocol's first count (images, pairs, snippets).
  const auto scored = [](const EvalResult& r) {
    return r.counts.empty() ? std::string("-") : std::to_string(r.counts[0].second) + " " + r.counts[0].first;
  };
  s << fmt::format("{:<22}", "scored");
  for (const auto& r : results) s << column(scored(r));
  s << "\n";
  for (size_t i = 0; i < results.size(); ++i) {
    s << names[i] << ":";
    for (const auto& c : results[i].counts) s << " " << c.first << " " << c.second;
    if (!results[i].test_drives_in_training.empty())
      s << " -- trained on " << results[i].test_drives_in_training.size() << " of the " << results[i].test_drives.size()
        << " test drives: " << join_list(results[i].test_drives_in_training, ", ");
    if (!results[i].training_drives_unknown.empty())
      s << " -- whether it trained on test drives is unknown: " << results[i].training_drives_unknown;
    s << "\n";
  }
  // Every difference other than the model, as a note: a column can only be read beside another
  // when they scored the same things the same way.
  const auto differ = [&](const std::string& what, const std::function<std::string(const EvalResult&)>& of) {
    bool same = true;
    for (const auto& r : results) same = same && of(r) == of(results[0]);
    if (same) return;
    s << "note: the columns differ in " << what << ":";
    for (size_t i = 0; i < results.size(); ++i) {
      const auto v = of(results[i]);
      s << (i ? "," : "") << " " << names[i] << " " << (v.empty() ? "(none)" : v);
    }
    s << "\n";
  };
  differ("split", [](const EvalResult& r) { return r.split; });
  differ("data root", [](const EvalResult& r) { return r.data_root; });
  differ("scaling", [](const EvalResult& r) { return r.scaling; });
  differ("precision", [](const EvalResult& r) { return r.precision; });
  differ("subset", [](const EvalResult& r) { return r.subset; });
  std::vector<std::string> count_keys;
  for (const auto& r : results)
    for (const auto& c : r.counts)
      if (std::find(count_keys.begin(), count_keys.end(), c.first) == count_keys.end()) count_keys.push_back(c.first);
  for (const auto& k : count_keys)
    differ("'" + k + "' (the metrics average over different sets)", [&](const EvalResult& r) {
      for (const auto& c : r.counts)
        if (c.first == k) return std::to_string(c.second);
      return std::string();
    });
  return s.str();
}

}  // namespace geo
