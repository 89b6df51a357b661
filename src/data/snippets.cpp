#include "data/snippets.h"

#include <stdexcept>
#include <utility>
#include <vector>

namespace geo {
namespace {

class SpreadSnippets : public SnippetSource {
 public:
  SpreadSnippets(std::shared_ptr<const SnippetSource> source, size_t n) : source_(std::move(source)) {
    const size_t total = source_->size();
    for (size_t k = 0; k < n; ++k) picks_.push_back(n == 1 ? 0 : k * (total - 1) / (n - 1));
  }
  size_t size() const override { return picks_.size(); }
  Snippet get(size_t index) const override { return source_->get(picks_.at(index)); }
  std::string id(size_t index) const override { return source_->id(picks_.at(index)); }
  int64_t seq_length() const override { return source_->seq_length(); }

 private:
  std::shared_ptr<const SnippetSource> source_;
  std::vector<size_t> picks_;
};

}  // namespace

std::shared_ptr<const SnippetSource> spread_snippets(std::shared_ptr<const SnippetSource> source, size_t n) {
  if (n == 0) throw std::invalid_argument("spread_snippets: n must be at least 1");
  if (source->size() <= n) return source;
  return std::make_shared<SpreadSnippets>(std::move(source), n);
}

}  // namespace geo
