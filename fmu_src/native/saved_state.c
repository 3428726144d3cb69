/* FMU states in bytes (model.h, SavedState): the serialized form both FMI layers use for
 * fmi2SerializeFMUstate / fmi3SerializeFMUState, with the layer's mark so that one layer's
 * state is refused by the other.  A file of its own, so that a build replacing model.c (the
 * benchmark's floor model) keeps it.
 */
#include <string.h>
#include "model.h"

typedef struct {
    char magic[8];
    unsigned int state_size;
    char guid[48];
    int model_exchange;
} StateHeader;

size_t model_serialized_size(void)
{
    return sizeof(StateHeader) + sizeof(ModelState);
}

void model_serialize(const SavedState *saved, const char magic[8], unsigned char *bytes)
{
    StateHeader header;
    memset(&header, 0, sizeof header);
    memcpy(header.magic, magic, sizeof header.magic);
    header.state_size = (unsigned int)sizeof(ModelState);
    strncpy(header.guid, FB_GUID, sizeof header.guid - 1);
    header.model_exchange = saved->model_exchange;
    memcpy(bytes, &header, sizeof header);
    memcpy(bytes + sizeof header, &saved->state, sizeof(ModelState));
}

int model_deserialize(const unsigned char *bytes, size_t size, const char magic[8], SavedState *saved)
{
    StateHeader header;
    if (size != model_serialized_size()) return MODEL_WRONG_SIZE;
    memcpy(&header, bytes, sizeof header);
    if (memcmp(header.magic, magic, sizeof header.magic) != 0 || header.state_size != sizeof(ModelState)
        || strncmp(header.guid, FB_GUID, sizeof header.guid) != 0
        || (header.model_exchange != 0 && header.model_exchange != 1))
        return MODEL_NOT_OURS;
    memcpy(&saved->state, bytes + sizeof header, sizeof(ModelState));
    saved->model_exchange = header.model_exchange;
    return 0;
}
