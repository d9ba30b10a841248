// Participant::topic takes ownership of the type it is given: every instance is freed, also the one passed for a topic
// that already exists (it leaked: LeakSanitizer found it in IntestineOrganTest, where a reader and the organ's writer
// both ask for surgsim/body_state).
#include "dds_support.h"

#include <gtest/gtest.h>

#include <string>

#include "support/test_domain.h"
#include "surgsim_types.h"

namespace surgsim {
namespace {

int g_alive = 0;  // instances of CountedType not yet destroyed

struct CountedType : msg::ToolCommandPubSubType {
  CountedType() { ++g_alive; }
  ~CountedType() override { --g_alive; }
};

TEST(DdsParticipant, TopicFreesEveryTypeItIsGivenAlsoForAnExistingTopic) {
  g_alive = 0;
  {
    dds::DdsOptions o;
    o.domain = test::reserve_test_domain();
    o.profiles_file = std::string(SURGSIM_TEST_CONFIG_DIR) + "/dds/profiles.xml";
    o.name = "surgsim_dds_support_test";
    dds::Participant participant(o);
    auto* first = participant.topic("surgsim_test/counted", new CountedType());
    ASSERT_NE(first, nullptr);
    EXPECT_EQ(participant.topic("surgsim_test/counted", new CountedType()), first);  // the same topic
    EXPECT_EQ(participant.topic("surgsim_test/counted_too", new CountedType()),
              participant.topic("surgsim_test/counted_too", new CountedType()));
    EXPECT_LE(g_alive, 1) << "a type given for an existing topic (or an already registered type) is freed at once";
  }
  EXPECT_EQ(g_alive, 0) << "the registered type is freed with the participant";
}

}  // namespace
}  // namespace surgsim
