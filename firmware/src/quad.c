#include "quad.h"

void quad_init(qdec_t *q, uint8_t ab)
{
    q->count = 0;
    q->state = ab & 3;
    q->errors = 0;
}
