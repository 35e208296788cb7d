/**
 * @file message_pool.h
 * @brief Output messages reused from pair to pair: a large message (the 640x480 scene-flow cloud is 11 MB) allocated
 * afresh every pair costs a page fault per 4 KiB page on first touch, and on a loaded or virtualised machine those
 * faults took most of the nodelet's own work (docs/PERFORMANCE.md, "Nodelet overhead per pair").
 */
#pragma once

#include <cstddef>
#include <vector>

#include <boost/make_shared.hpp>
#include <boost/shared_ptr.hpp>

namespace mc_flow_ros {

/// @brief A few messages of one type, handed out again once nobody else holds them: a subscriber in the same process
/// keeps a published message as long as it holds the pointer, and a message for remote subscribers is serialised
/// during publish(), so a message whose only owner is the pool is free. Its buffers keep their capacity, so refilling
/// it at the same size touches no fresh memory. The fill must write every field and byte it publishes. Used by one
/// thread (the nodelet's pair callback).
template <typename Message>
class MessagePool {
 public:
  /// @brief A message only the pool holds (its contents are the last pair's), or a new one, kept for later pairs while
  /// fewer than `kMessages` are pooled.
  boost::shared_ptr<Message> take() {
    for (const boost::shared_ptr<Message>& m : messages_)
      if (m.use_count() == 1) return m;
    auto fresh = boost::make_shared<Message>();
    if (messages_.size() < kMessages) messages_.push_back(fresh);
    return fresh;
  }
  std::size_t size() const { return messages_.size(); }

 private:
  // One being published, one a slow subscriber still holds, one spare.
  static constexpr std::size_t kMessages = 3;
  std::vector<boost::shared_ptr<Message>> messages_;
};

}  // namespace mc_flow_ros
