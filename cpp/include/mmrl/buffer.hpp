// A read-mostly array that either owns its values (a std::vector) or borrows read-only
// memory that someone else keeps alive: a numpy array, or a page of Ray's shared-memory
// object store that many worker processes map at once. The database's large per-frame
// arrays are Buffers, so a database built from borrowed arrays costs each process no copy.
//
// Reading is the same either way. Writing goes through mutable_data(), which first copies a
// borrowed buffer into an owned vector (the borrowed memory may be read-only), or assigns a
// whole new vector: only offline code (building, reweighting) writes.
#pragma once

#include <algorithm>
#include <cstddef>
#include <memory>
#include <utility>
#include <vector>

namespace mmrl {

template <class T>
class Buffer {
 public:
  using value_type = T;
  Buffer() = default;
  Buffer(std::vector<T> values) : owned_(std::move(values)) { point_at_owned(); }  // NOLINT: implicit by design
  Buffer(const Buffer& o) : owned_(o.owned_), owner_(o.owner_), data_(o.data_), size_(o.size_) {
    if (!owner_) point_at_owned();
  }
  Buffer(Buffer&& o) noexcept : owned_(std::move(o.owned_)), owner_(std::move(o.owner_)), data_(o.data_), size_(o.size_) {
    if (!owner_) point_at_owned();
    o.reset_to_empty();
  }
  Buffer& operator=(Buffer o) noexcept {
    owned_ = std::move(o.owned_);
    owner_ = std::move(o.owner_);
    data_ = o.data_;
    size_ = o.size_;
    if (!owner_) point_at_owned();
    o.reset_to_empty();
    return *this;
  }
  Buffer& operator=(std::vector<T> values) { return *this = Buffer(std::move(values)); }

  // Borrows n values at data; owner keeps them alive (and is released with the last copy).
  static Buffer borrow(const T* data, size_t n, std::shared_ptr<const void> owner) {
    Buffer b;
    b.owner_ = std::move(owner);
    b.data_ = data;
    b.size_ = n;
    return b;
  }

  const T* data() const { return data_; }
  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  const T& operator[](size_t i) const { return data_[i]; }
  const T* begin() const { return data_; }
  const T* end() const { return data_ + size_; }
  friend bool operator==(const Buffer& a, const Buffer& b) {
    return a.size_ == b.size_ && std::equal(a.begin(), a.end(), b.begin());
  }
  friend bool operator!=(const Buffer& a, const Buffer& b) { return !(a == b); }
  // True while the values are someone else's memory.
  bool borrowed() const { return owner_ != nullptr; }

  // Writable values: a borrowed buffer is copied into an owned one first. To change the size,
  // assign a new vector.
  T* mutable_data() {
    if (owner_) {
      owned_.assign(data_, data_ + size_);
      owner_.reset();
      point_at_owned();
    }
    return owned_.data();
  }

 private:
  void point_at_owned() {
    data_ = owned_.data();
    size_ = owned_.size();
  }
  void reset_to_empty() {
    owned_.clear();
    owner_.reset();
    data_ = nullptr;
    size_ = 0;
  }

  std::vector<T> owned_;
  std::shared_ptr<const void> owner_;  // non-null: data_ is borrowed
  const T* data_ = nullptr;
  size_t size_ = 0;
};

}  // namespace mmrl
