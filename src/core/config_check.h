// Validation of a config's sections: the checker every section's validate() reports to (the key's
// path, its value as the configuration shows it, its YAML line) and the rules several share.
// Internal to core/config*.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <map>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/config_base.h"
#include "core/config_text.h"

namespace geo {
using namespace config_text;

// A value already written as the configuration shows it.
struct Shown {
  std::string text;
};
inline std::string to_text(const Shown& v) { return v.text; }

class Checker {
 public:
  // `lines`: where each key came from (Config::lines); `source`: the file, for the message.
  Checker(const std::map<std::string, int>& lines, std::string source) : lines_(lines), source_(std::move(source)) {}

  // RAII prefix for nested structs: Checker::Scope s(c, "stages[0]");
  class Scope {
   public:
    Scope(Checker& c, const std::string& name) : c_(c), saved_(c.prefix_) { c_.prefix_ = join(saved_, name); }
    ~Scope() { c_.prefix_ = saved_; }

   private:
    Checker& c_;
    std::string saved_;
  };

  // A section's checks (section.validate(*this)) under the key prefix `name`.
  template <class Section>
  void section(const std::string& name, const Section& s) {
    Scope scope(*this, name);
    s.validate(*this);
  }

  template <class T>
  void require(bool ok, const char* key, const T& value, const std::string& rule) {
    if (ok) return;
    const std::string path = join(prefix_, key);
    std::string where;
    auto it = lines_.find(path);
    if (it != lines_.end()) where = it->second > 0 ? " (line " + std::to_string(it->second) + ")" : " (from --set)";
    else where = " (default)";
    errors_.push_back("key '" + path + "' = " + to_text(value) + where + ": " + rule);
  }

  void fail_if_any() const {
    if (errors_.empty()) return;
    std::string msg = source_ + ": invalid configuration:";
    for (const auto& e : errors_) msg += "\n  " + e;
    throw ConfigError(msg);
  }

 private:
  const std::map<std::string, int>& lines_;
  std::string source_;
  std::string prefix_;
  std::vector<std::string> errors_;
};

// Every count of iterations is bounded where it is read, so that sums and products of counts (the
// total of the stages, iteration x batch) stay far from int64's limit: 1e12 iterations is more than
// any run can make.
inline constexpr int64_t kMaxCount = 1000000000000;
inline constexpr const char* kCountRange = "must be in 1..1000000000000";

// The keys of a section (camera, video) whose values differ from the section's defaults, with
// their values as the configuration shows them.
template <class Section>
std::vector<std::pair<std::string, std::string>> non_defaults(const Section& section) {
  Section given = section, plain;
  std::vector<std::pair<std::string, std::string>> a, b, out;
  auto into = [](std::vector<std::pair<std::string, std::string>>& list) {
    return [&list](const char* name, const auto& value) { list.emplace_back(name, to_text(value)); };
  };
  auto collect_a = into(a);
  auto collect_b = into(b);
  given.fields(collect_a);
  plain.fields(collect_b);
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].second != b[i].second) out.push_back(a[i]);
  return out;
}

inline bool one_of(const std::string& v, std::initializer_list<const char*> options) {
  for (const char* o : options)
    if (v == o) return true;
  return false;
}

}  // namespace geo
